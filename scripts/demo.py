#!/usr/bin/python3
"""The cc_log demo (see README): collect, learn, then the smart logger live on a simulated BWIBot."""
import sys

from cc_log.offline.demo import main

if __name__ == '__main__':
    sys.exit(main())
