"""Launch, parameters, demo, record and replay of the powered-descent stack."""

from glob import glob

from setuptools import find_packages, setup

package_name = "pd_bringup"

setup(
    name=package_name,
    version="0.3.0",
    packages=find_packages(exclude=["test", "tests"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="pd team",
    maintainer_email="pd@example.org",
    description="Launch, parameters, demo, record and replay of the powered-descent stack.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "pd_demo = pd_bringup.demo:main",
            "pd_record = pd_bringup.record:main",
            "pd_replay = pd_bringup.replay:main",
            "pd_lifecycle_manager = pd_bringup.lifecycle_manager:main",
        ],
    },
)
