"""tools/test_summary.py: the one closing line of ./dev.sh test, and what counts as failed (in CI too)."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
TOOL = os.path.join(ROOT, 'tools', 'test_summary.py')

CASES = '''<?xml version="1.0"?>
<testsuites><testsuite name="s">
  <testcase classname="t" name="ok"/>
  <testcase classname="t" name="broken"><failure message="assert 1 == 2&#10;where 1 = f()"/></testcase>
  <testcase classname="t" name="crashed"><error message="boom"/></testcase>
  <testcase classname="t" name="no_rosbag"><skipped message="could not import 'rosbag': No module named 'rosbag'"/>
  </testcase>
  <testcase classname="t" name="no_jq"><skipped type="pytest.skip">jq is not installed</skipped></testcase>
  <testcase classname="t" name="no_rosrun"><skipped type="pytest.skip" message="needs roscore and rosrun"/></testcase>
  <testcase classname="t" name="not_root"><skipped message="not root (a tmpfs mount needs root)"/></testcase>
  <testcase classname="t" name="known_gap"><skipped type="pytest.xfail" message="json-xz reorders"/></testcase>
</testsuite></testsuites>
'''


def summary(directory, ci):
    env = dict(os.environ)
    env.pop('CI', None)
    if ci is not None:
        env['CI'] = ci
    result = subprocess.run([sys.executable, TOOL, str(directory)], env=env, stdout=subprocess.PIPE,
                            universal_newlines=True, timeout=60)
    return result.returncode, result.stdout.splitlines()


def write(directory, name, text):
    directory.mkdir(parents=True, exist_ok=True)
    (directory / name).write_text(text)


def test_failures_errors_and_skips_are_counted(tmp_path):
    write(tmp_path / 'cc_log', 'pytest-a.xml', CASES)
    code, lines = summary(tmp_path, None)
    assert lines[-1] == '1 passed, 2 failed, 5 skipped' and code == 1
    assert lines[0].split() == ['cc_log/pytest-a.xml', '1', 'passed,', '2', 'failed,', '5', 'skipped']
    broken = lines.index('FAILED t.broken')
    assert lines[broken + 1:broken + 3] == ['    assert 1 == 2', '    where 1 = f()']
    assert 'FAILED t.crashed' in lines and '    boom' in lines


def test_in_ci_a_skip_fails_unless_it_is_not_about_a_dependency(tmp_path):
    write(tmp_path, 'a.xml', CASES)
    for ci in ('true', '1'):
        code, lines = summary(tmp_path, ci)
        assert lines[-1] == '1 passed, 5 failed, 2 skipped' and code == 1
        named = [line for line in lines if 'skipped in CI' in line]
        assert len(named) == 3 and any('t.no_rosbag' in line for line in named)
        assert any('t.no_jq' in line and 'jq is not installed' in line for line in named)
        assert any('t.no_rosrun' in line and 'needs roscore and rosrun' in line for line in named)
        assert not any('t.not_root' in line or 't.known_gap' in line for line in named)
    assert summary(tmp_path, 'false')[1][-1] == '1 passed, 2 failed, 5 skipped'


def test_all_passed_is_success_and_nothing_ran_is_failure(tmp_path):
    write(tmp_path, 'a.xml', '<testsuite><testcase classname="t" name="ok"/>'
                             '<testcase classname="t" name="gap"><skipped type="pytest.xfail"/></testcase></testsuite>')
    code, lines = summary(tmp_path, 'true')
    assert code == 0 and lines[-1] == '1 passed, 0 failed, 1 skipped' and not any('FAILED' in x for x in lines)
    empty = tmp_path / 'empty'
    empty.mkdir()
    assert summary(empty, None) == (1, ['no test ran'])


def test_an_unreadable_result_file_is_a_failure(tmp_path):
    write(tmp_path, 'a.xml', '<testsuite><testcase classname="t" name="ok"/></testsuite>')
    write(tmp_path, 'b.xml', '<testsuite><testcase')
    code, lines = summary(tmp_path, None)
    assert code == 1 and lines[-1] == '1 passed, 1 failed, 0 skipped'
    assert any(line.startswith('FAILED ') and 'b.xml: unreadable result file' in line for line in lines)
    assert [line.split()[:3] for line in lines[:2]] == [['a.xml', '1', 'passed,'], ['b.xml', '0', 'passed,']]


def test_a_rostest_launch_counts_only_when_it_fails(tmp_path):
    launch = '<testsuite><testcase classname="rostest.runner.RosTest" name="testwindow"%s</testsuite>'
    write(tmp_path, 'rostest-test_window.xml', launch % '/>')
    write(tmp_path, 'rosunit-window.xml', '<testsuite><testcase classname="w" name="test_1"/>'
                                          '<testcase classname="w" name="test_2"/></testsuite>')
    assert summary(tmp_path, 'true')[1][-1] == '2 passed, 0 failed, 0 skipped'
    write(tmp_path, 'rostest-test_window.xml', launch % '><failure message="no results"/></testcase>')
    code, lines = summary(tmp_path, 'true')
    assert lines[-1] == '2 passed, 1 failed, 0 skipped' and code == 1
