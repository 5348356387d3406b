#!/usr/bin/python3
"""The node of record.launch: the smart logger when a model exists, else the collect logger (see README)."""
import sys

from cc_log.nodes.launcher import main

if __name__ == '__main__':
    sys.exit(main())
