#!/usr/bin/python3
"""The collect logger node: logs everything in rotated window files plus feature vectors (see README)."""
import sys

from cc_log.collect_node import main

if __name__ == '__main__':
    sys.exit(main())
