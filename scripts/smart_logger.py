#!/usr/bin/python3
"""The smart logger node: keeps only the sensor data around anomalies (see README)."""
import sys

from cc_log.nodes.launcher import script_main

if __name__ == '__main__':
    sys.exit(script_main('smart_node'))
