#!/usr/bin/python3
"""The simulated BWIBot node: odometry (and IMU) at 100 Hz with labelled anomalies (see cc_log.nodes.sim_node)."""
import sys

from cc_log.nodes.launcher import script_main

if __name__ == '__main__':
    sys.exit(script_main('sim_node'))
