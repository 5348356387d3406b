#!/usr/bin/python3
"""The simulated BWIBot node: odometry (and IMU) at 100 Hz with labelled anomalies (see cc_log.sim_node)."""
import sys

from cc_log.sim_node import main

if __name__ == '__main__':
    sys.exit(main())
