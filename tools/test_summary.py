#!/usr/bin/python3
"""Tally JUnit XML results below the given directories: a line per result file, each failure with the first
lines of its message, and last the one line 'N passed, N failed, N skipped'.

Exit status is non-zero when any test failed or errored, or when no test ran at all. In CI (CI=true) a
skipped test counts as failed unless its reason says it does not apply here for a reason that is not a
missing dependency (``NOT_A_DEPENDENCY``: not running as root; an expected failure of a known gap):
cc_log declares everything its tests need, so any other skip ("could not import", "not installed",
"needs rosrun", "no real bags") hides a broken install.
"""
import glob
import os
import re
import sys
import xml.etree.ElementTree as ET

#: Reasons of a skip that are not a missing dependency of cc_log: the only skips that stay skips in CI.
NOT_A_DEPENDENCY = re.compile(r'\bnot root\b|only be mounted by root|needs root', re.IGNORECASE)
#: classname of the one test case rostest writes for a whole .test file (it fails when the launch fails).
ROSTEST_LAUNCH = 'rostest.runner.RosTest'
MESSAGE_LINES = 20  # of each failure's message


def in_ci(environ=os.environ):
    """True when running under CI (the CI variable set to anything but empty, 0 or false)."""
    return environ.get('CI', '').strip().lower() not in ('', '0', 'false', 'no')


def skip_reason(skipped):
    """The reason a <skipped> element gives: its message and its text."""
    return ' '.join(part for part in (skipped.get('message', ''), skipped.text or '') if part).strip()


def failure_text(element):
    """The first lines of a <failure> or <error>: its message, else its text."""
    lines = (element.get('message') or element.text or '').strip().splitlines()
    return '\n'.join('    ' + line for line in lines[:MESSAGE_LINES])


def tally(directory, strict_skips=False, files=None):
    """Return (passed, failed, skipped, failed test names) over every XML file below directory.

    ``strict_skips``: a skip counts as failed (named with its reason) unless it is an expected failure or its
    reason matches ``NOT_A_DEPENDENCY``. ``files``: a
    list that gets (path, passed, failed, skipped) of each result file."""
    passed = failed = skipped = 0
    failures = []
    for path in sorted(glob.glob(os.path.join(directory, '**', '*.xml'), recursive=True)):
        before = (passed, failed, skipped)
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as error:
            failed += 1
            failures.append('%s: unreadable result file (%s)' % (path, error))
            root = ET.Element('testsuite')
        for case in root.iter('testcase'):
            name = '%s.%s' % (case.get('classname', ''), case.get('name', ''))
            skip = case.find('skipped')
            broken = case.find('failure') if case.find('failure') is not None else case.find('error')
            if broken is None and case.get('classname') == ROSTEST_LAUNCH:
                continue  # the launch of a rostest that ran: its test cases are counted from its rosunit file
            if broken is not None:
                failed += 1
                failures.append('%s\n%s' % (name, failure_text(broken)) if failure_text(broken) else name)
            elif skip is not None and strict_skips and skip.get('type') != 'pytest.xfail' \
                    and not NOT_A_DEPENDENCY.search(skip_reason(skip)):
                failed += 1
                failures.append('%s: skipped in CI, where every dependency is installed (%s)' % (
                    name, skip_reason(skip)[:200]))
            elif skip is not None:
                skipped += 1
            else:
                passed += 1
        if files is not None:
            files.append((os.path.relpath(path, directory), passed - before[0], failed - before[1],
                          skipped - before[2]))
    return passed, failed, skipped, failures


def main(argv, environ=os.environ):
    passed = failed = skipped = 0
    failures = []
    for directory in argv[1:]:
        files = []
        counts = tally(directory, strict_skips=in_ci(environ), files=files)
        passed, failed, skipped = passed + counts[0], failed + counts[1], skipped + counts[2]
        failures += counts[3]
        for path, *figures in files:
            print('  %-44s %d passed, %d failed, %d skipped' % (path, *figures))
    for name in failures:
        print('FAILED %s' % name)
    if passed + failed == 0:
        print('no test ran')
        return 1
    print('%d passed, %d failed, %d skipped' % (passed, failed, skipped))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
