"""Python package setup for catkin: installs the cc_log library from src/."""
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=['cc_log', 'cc_log.features', 'cc_log.triggers'], package_dir={'': 'src'}))
