"""pd_core: physics, optimal control and learning for powered descent (no rclpy).

Both an ament_python package (colcon builds it into ros2_ws) and a pip-installable
library (`pip install -e pd_core`).
"""

from setuptools import find_packages, setup

package_name = "pd_core"

setup(
    name=package_name,
    version="0.3.0",
    packages=find_packages(exclude=["test", "tests"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="pd team",
    maintainer_email="pd@example.org",
    description="Powered-descent physics, OCP demonstrations and DQN training (no ROS).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "pd-ocp = pd_core.cli.ocp:main",
            "pd-train = pd_core.cli.train:main",
            "pd-demos = pd_core.cli.demos:main",
            "pd-eval = pd_core.cli.evaluate:main",
            "pd-sweep = pd_core.cli.sweep:main",
        ],
    },
)
