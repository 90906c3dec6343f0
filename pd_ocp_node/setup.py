"""Optimal-trajectory service node of the powered-descent stack (ament_python)."""

from setuptools import find_packages, setup

package_name = "pd_ocp_node"

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
    description="Optimal-trajectory service node of the powered-descent stack (ament_python).",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "pd_ocp_node = pd_ocp_node.node:main",
        ],
    },
)
