"""Lint is part of the test run: flake8 (the project's .flake8) and catkin_lint -W2 report nothing."""
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def run(args, cwd):
    return subprocess.run(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
                          timeout=300)


def test_flake8_reports_nothing():
    result = run([sys.executable, '-m', 'flake8'], ROOT)
    assert result.returncode == 0 and result.stdout.strip() == '', 'flake8 (.flake8):\n' + result.stdout


def test_catkin_lint_reports_nothing(tmp_path):
    catkin_lint = shutil.which('catkin_lint')
    assert catkin_lint, 'catkin_lint is not installed (Debian package catkin-lint, rosdep key python3-catkin-lint)'
    package = tmp_path / 'cc_log'  # catkin_lint wants the directory named as the package
    package.symlink_to(ROOT)
    result = run([catkin_lint, '-W2', '--quiet', str(package)], str(tmp_path))
    problems = [line for line in result.stdout.splitlines() if line.startswith('cc_log:')]
    assert result.returncode == 0 and not problems, 'catkin_lint -W2:\n' + result.stdout
