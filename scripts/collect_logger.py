#!/usr/bin/python3
"""The collect logger node: logs everything in rotated window files plus feature vectors (see README)."""
import sys

from cc_log.nodes.launcher import script_main

if __name__ == '__main__':
    sys.exit(script_main('collect_node'))
