"""ament_python / pip package definition for pmsm_sysid."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "pmsm_sysid"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    package_data={PACKAGE: ["data/*.yaml", "data/*.xml", "py.typed", "report/templates/*.j2"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/msg_schemas", glob("msg_schemas/*.msg")),
    ],
    python_requires=">=3.10",
    # the whole offline tool and the Python API; no ROS wheels (bags are read with rosbags;
    # ruamel.yaml.clib: rosbags parses each bag's metadata with ruamel.yaml, whose C reader
    # takes about 8 ms off every bag read or written)
    install_requires=["numpy", "scipy", "rosbags>=0.10", "PyYAML", "jsonschema", "matplotlib",
                      "Jinja2", "rich",
                      "ruamel.yaml.clib; platform_python_implementation == 'CPython'"],
    extras_require={
        # pytest 9.2 ignores the test-group suffix pytest-xdist 3.8 gives a test, so
        # `--dist loadgroup` would split a module's shared runs over both test processes
        "test": ["pytest<9.2", "pytest-xdist", "pytest-timeout", "hypothesis", "ruff", "mypy",
                 "types-PyYAML", "scipy-stubs", "pdoc", "colcon-core", "colcon-ros",
                 "colcon-python-setup-py", "dask[distributed]", "pyarrow"],
        # `pmsm-sysid fleet` / ps.fleet: many recordings in parallel on Dask distributed (a
        # local cluster or an existing one), the table in Parquet
        "fleet": ["dask[distributed]", "pyarrow"],
        # the live verbs (run, record, replay, monitor) and the nodes: ROS 2 Jazzy wheels;
        # not needed where a ROS 2 Jazzy installation is sourced
        "ros": ["ros-jazzy-rclpy~=7.1", "ros-jazzy-rmw-fastrtps-cpp~=8.4",
                "ros-jazzy-common-interfaces~=5.3"],
        "bench": ["sysidentpy==0.9.0", "numpy<=2.3.5"],
    },
    zip_safe=True,
    maintainer="pmsm_sysid maintainers",
    description="Online NARX identification and GFRF analysis of a linear PMSM servo (ROS 2).",
    license="Apache-2.0",
    entry_points={
        # the tool, one executable per node (`ros2 run pmsm_sysid sim|identifier|gfrf|diagnose`,
        # launch files); colcon installs them in lib/pmsm_sysid (setup.cfg), pip in bin/
        "console_scripts": ["pmsm-sysid = pmsm_sysid.cli:main",
                            "sim = pmsm_sysid.nodes.executables:sim",
                            "identifier = pmsm_sysid.nodes.executables:identifier",
                            "gfrf = pmsm_sysid.nodes.executables:gfrf",
                            "diagnose = pmsm_sysid.nodes.executables:diagnose"],
        # fixtures ros_env, ros_context, ros_executor, sim_motor for any project's tests
        "pytest11": ["pmsm_sysid = pmsm_sysid.testing.pytest_plugin"],
    },
)
