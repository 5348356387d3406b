#!/usr/bin/python3
"""The smart logger node: keeps only the sensor data around anomalies (see README)."""
import sys

from cc_log.smart_node import main

if __name__ == '__main__':
    sys.exit(main())
