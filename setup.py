"""Python package setup for catkin: installs the cc_log library from src/."""
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

PACKAGES = ['cc_log', 'cc_log.features', 'cc_log.formats', 'cc_log.triggers']

setup(**generate_distutils_setup(packages=PACKAGES, package_dir={'': 'src'}))
