"""ament_python / pip build script for sma_wrist.

The same file serves `colcon build` on a ROS 2 machine (data_files land in
share/sma_wrist, executables in lib/sma_wrist for `ros2 run`) and `pip install .`
on a plain Python machine (the embedded runtime replaces rclpy there).
"""

from glob import glob

from setuptools import find_packages, setup

package_name = 'sma_wrist'

NODES = {
    'plant_sim': 'sma_wrist.nodes.plant_sim:main',
    'hysteresis_compensator': 'sma_wrist.nodes.hysteresis_compensator:main',
    'adaptive_controller': 'sma_wrist.nodes.adaptive_controller:main',
    'tem_controller': 'sma_wrist.nodes.tem_controller:main',
    'trajectory_generator': 'sma_wrist.nodes.trajectory_generator:main',
    'hardware_bridge': 'sma_wrist.nodes.hardware_bridge:main',
    'twin_monitor': 'sma_wrist.nodes.twin_monitor:main',
}

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        # the Foxglove layout of the live view (doc/howto/live_view.md)
        ('share/' + package_name + '/config/foxglove', glob('config/foxglove/*.json')),
        ('share/' + package_name + '/msg_defs', glob('msg_defs/*')),
    ],
    python_requires='>=3.10',
    install_requires=[
        'setuptools',
        'numpy>=1.21',
        'scipy>=1.8',
        'rosbags>=0.10',
        'mcap>=1.1',
        # ROS params files and the msg_defs contract are YAML; ROS itself ships python3-yaml.
        'PyYAML>=5.4',
        # hardware_bridge's serial line to the wrist controller (sma_wrist/hw/link.py).
        'pyserial>=3.4',
    ],
    extras_require={
        # dask[distributed]: the sweep's --scheduler test (LocalCluster, ~5 s) runs in CI, not skipped
        # pytest-xdist: the suite is CPU-bound and was serial, one of CI's 2 cores idle
        # (`-n 2 --dist loadgroup` in .ci/run; test/conftest.py groups module fixtures)
        # ruff: test_lint.py checks the code against ruff.toml; pinned to a minor release because the formatter's
        # style may change between them
        # foxglove-sdk + websockets: test_live.py serves a run and reads it with a real WebSocket client in CI
        'test': [
            'pytest>=7',
            'hypothesis>=6',
            'dask[distributed]>=2023.1',
            'pytest-xdist>=3.0',
            'ruff>=0.17,<0.18',
            'foxglove-sdk>=0.30.3,<0.31',
            'websockets>=13',
        ],
        # Reports write PNG plots; optional so a headless robot install stays small.
        'plot': ['matplotlib>=3.5'],
        # Compiles the per-sample plant step (sma_wrist/core/plant/kernel.py): ~1 us instead of
        # ~0.3 ms per 1 kHz step, which is what makes the node graph run faster than real time.
        'fast': ['numba>=0.57'],
        # sma-wrist sweep --scheduler ADDRESS: the chunks run on a Dask distributed cluster
        'dask': ['dask[distributed]>=2023.1'],
        # The documentation (doc/, `sphinx-build -W --keep-going -b html doc doc/_build/html`). pip picks Sphinx
        # 8.1 + MyST 4.0 on Humble's Python 3.10 (Sphinx 8.2+ and MyST 5 need 3.11+), Sphinx 9.0 / 9.1 + MyST 5.2
        # on 3.11 / Jazzy's 3.12; the -W build was run clean with each (8.1.3 + 4.0.1, 9.0.4 + 5.2.0, 9.1.1 +
        # 5.2.0), the bounds keep to them (warnings and MyST's Markdown change between majors).
        # sphinx_rtd_theme is the theme rosdoc2 uses.
        # sma-wrist run --foxglove: the live view over the Foxglove WebSocket protocol (sma_wrist/runtime/live.py).
        # 0.30 is the release it was written and measured against; the SDK was still changing its API
        # between minor releases (0.x), hence the bound.
        'live': ['foxglove-sdk>=0.30.3,<0.31'],
        'docs': ['sphinx>=8.1,<10', 'myst-parser>=4.0,<6', 'sphinx_rtd_theme>=3.0,<4'],
    },
    zip_safe=True,
    maintainer='sma_wrist developers',
    maintainer_email='dev@sma-wrist.invalid',
    description='SMA-muscle wrist: SD-GPI hysteresis plant, controllers, embedded rclpy runtime.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in NODES.items()]
        + ['sma-wrist = sma_wrist.cli:main'],
    },
)
