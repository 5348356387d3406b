"""Python package setup for catkin: installs the cc_log library from src/."""
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

PACKAGES = ['cc_log', 'cc_log.base', 'cc_log.buffer', 'cc_log.learning', 'cc_log.logger', 'cc_log.features',
            'cc_log.triggers', 'cc_log.storage', 'cc_log.storage.bag', 'cc_log.storage.formats', 'cc_log.nodes',
            'cc_log.offline', 'cc_log.offline.cli', 'cc_log.sim']

setup(**generate_distutils_setup(packages=PACKAGES, package_dir={'': 'src'}))
