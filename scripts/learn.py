#!/usr/bin/python3
"""Learn mode: train the anomaly model, validate it, save it (no roscore; see README)."""
import sys

from cc_log.offline.learn_main import main

if __name__ == '__main__':
    sys.exit(main())
