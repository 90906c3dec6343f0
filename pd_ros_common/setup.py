"""What the nodes, the bringup tools and the tests share (ament_python)."""

from setuptools import find_packages, setup

package_name = "pd_ros_common"

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
    description="Topic and service names, QoS, message conversion, node --help, parameter "
    "checks, process supervision and the ROS domain claim of the powered-descent stack.",
    license="Apache-2.0",
)
