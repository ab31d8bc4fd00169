from glob import glob

from setuptools import find_packages, setup

package_name = "riann_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["riann_ros", "riann_ros.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.json")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    # riann-bag-eval --scheduler (a Dask cluster); the full pinned set: requirements-cluster.txt
    extras_require={"cluster": ["dask==2026.8.0", "distributed==2026.8.0", "bokeh==3.9.2"]},
    zip_safe=True,
    maintainer="riann_ros developers",
    maintainer_email="riann-ros@example.org",
    description="Plug-and-play IMU attitude estimation for ROS 2 (RIANN, Madgwick, Mahony, VQF, RIANN+VQF)",
    license="Apache-2.0",
    python_requires=">=3.11",
    entry_points={
        "console_scripts": [
            "riann_node = riann_ros.nodes.riann_node:main",
            "madgwick_node = riann_ros.nodes.madgwick_node:main",
            "mahony_node = riann_ros.nodes.mahony_node:main",
            "vqf_node = riann_ros.nodes.vqf_node:main",
            "consensus_node = riann_ros.nodes.consensus_node:main",
            "riann-bag-convert = riann_ros.cli.convert:main",
            "riann-bag-eval = riann_ros.cli.evaluate:main",
            "riann-topic = riann_ros.cli.topic:main",
            "riann-mag-calibrate = riann_ros.cli.magcal:main",
        ],
    },
)
