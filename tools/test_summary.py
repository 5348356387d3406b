#!/usr/bin/python3
"""Tally JUnit XML results below the given directories; print 'N passed, N failed, N skipped'.

Exit status is non-zero when any test failed or errored, or when no test ran at all.
"""
import glob
import os
import sys
import xml.etree.ElementTree as ET


def tally(directory):
    """Return (passed, failed, skipped, failed test names) over every XML file below directory."""
    passed = failed = skipped = 0
    failures = []
    for path in sorted(glob.glob(os.path.join(directory, '**', '*.xml'), recursive=True)):
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as error:
            failed += 1
            failures.append('%s: unreadable result file (%s)' % (path, error))
            continue
        for case in root.iter('testcase'):
            name = '%s.%s' % (case.get('classname', ''), case.get('name', ''))
            if case.find('failure') is not None or case.find('error') is not None:
                failed += 1
                failures.append(name)
            elif case.find('skipped') is not None:
                skipped += 1
            else:
                passed += 1
    return passed, failed, skipped, failures


def main(argv):
    passed = failed = skipped = 0
    failures = []
    for directory in argv[1:]:
        counts = tally(directory)
        passed, failed, skipped = passed + counts[0], failed + counts[1], skipped + counts[2]
        failures += counts[3]
    for name in failures:
        print('FAILED %s' % name)
    if passed + failed == 0:
        print('no test ran')
        return 1
    print('%d passed, %d failed, %d skipped' % (passed, failed, skipped))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
