"""ament_python package finger_sim: `colcon build` on a ROS 2 machine, or `pip install .[ros]` in a venv."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "finger_sim"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/config/ros2_control", glob("config/ros2_control/*")),
        (f"share/{PACKAGE}/config/hands", glob("config/hands/*.yaml")),
        (f"share/{PACKAGE}/config/foxglove", glob("config/foxglove/*.json")),
        (f"share/{PACKAGE}/config/tasks", glob("config/tasks/*.yaml")),
        (f"share/{PACKAGE}/urdf", glob("urdf/*.urdf")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    package_data={PACKAGE: ["py.typed", "data/*.json", "view/*.html", "view/*.js", "view/*.css", "view/vendor/*"]},
    python_requires=">=3.10",
    install_requires=["numpy", "scipy", "pyyaml", "matplotlib", "tqdm", "mcap>=1.5,<2", "mcap-ros2-support>=0.6", "rosbags>=0.10", "numba",
                      "plotly>=7,<8", "SALib", "pydantic>=2"],
    extras_require={
        # ROS 2 Jazzy's Python stack from PyPI, for machines without a ROS install.
        "ros": [
            "ros-jazzy-rclpy[fastrtps]",
            "ros-jazzy-sensor-msgs",
            "ros-jazzy-std-msgs",
            "ros-jazzy-geometry-msgs",
            "ros-jazzy-rosgraph-msgs",
            "ros-jazzy-std-srvs",
            "ros-jazzy-diagnostic-msgs",
            "ros-jazzy-visualization-msgs",
        ],
        "test": ["pytest", "pytest-timeout", "hypothesis", "rosbags", "yourdfpy", "colcon-common-extensions",
                 "playwright", "pillow",  # playwright drives the system Chromium (make test installs it)
                 "distributed", "pyarrow", "jsonschema"],
        # `finger-sim sweep --dask ADDRESS` and Parquet output
        "cluster": ["distributed", "pyarrow"],
        "bench": ["mujoco"],
    },
    zip_safe=True,
    maintainer="finger_sim developers",
    description="Constrained dynamics of a four-bar prosthetic finger with a ROS 2 node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "finger-sim = finger_sim.cli:main",
            "finger_node = finger_sim.ros.node:main",
            "finger_hand = finger_sim.ros.hand:main",
            "finger_pd_controller = finger_sim.ros.pd_controller:main",
            "finger_grip_controller = finger_sim.ros.grip_controller:main",
            "finger_task_controller = finger_sim.ros.task_controller:main",
            "finger_replay = finger_sim.ros.replay:main",
        ],
    },
)
