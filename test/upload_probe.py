#!/usr/bin/python3
"""Upload command of record_dropin.test: appends the file's path to LIST; fails (status 3) for context files."""
import os
import sys

listing, path = sys.argv[1], sys.argv[2]
with open(listing, 'a') as stream:
    stream.write(path + '\n')
if os.sep + 'context' + os.sep in path:
    sys.stderr.write('upload refused: %s\n' % path)
    sys.exit(3)
