#!/usr/bin/env python3
"""How well does cc_log detect? One entry for every detection benchmark: a part, then that part's own flags.

    cd <tree> && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/detection.py                          # the parts, what each answers, where its figures go
    python3 bench/detection.py runs --seeds 0           # a part with its own flags (``PART --help``: them)
    python3 bench/detection.py detectors --quick

Each part is the ``main`` of one module of bench/ (its docstring says the protocol in full); bench/README.md maps
every question to its command and to the section of docs/RESULTS.md or docs/DETECTION.md it re-makes.
"""
import collections
import importlib
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

# part -> (module of bench/, what it answers)
PARTS = collections.OrderedDict([
    ('sim', ('detection_sim', "the paper's Table 1 protocol on the simulated BWIBot")),
    ('real', ('detection_real', 'the real bags with known anomalies: Husky second half, ALFA, Sequor')),
    ('injected', ('injected_husky', 'simulator anomalies injected into the Husky run; windows that fit the event')),
    ('runs', ('detection_runs', 'every real run with odometry, trained on its first part or the robot\'s other runs')),
    ('heldout', ('detection_heldout', 'held-out public robots, as a user runs cclog collect, learn, replay')),
    ('detectors', ('detectors', "cc_log's defaults against the standard detectors on every real robot")),
    ('ranker', ('detection_ranker', 'a two-class ranker gating the one-class model (not adopted)')),
    ('tuning', ('detection_sim_tuning', 'the demo and the defaults tuned on the simulator')),
    ('signals', ('imu_collision', 'which signal each anomaly needs: odometry, IMU, command, goal status')),
    ('online', ('learn_online', 'online learning of nominal: false windows before and after refits')),
    ('tune', ('tune_choice', '`cclog tune` choosing the feature window and classify rate')),
])


def usage():
    """The parts, one line each."""
    lines = [__doc__.split('\n\n')[0], '', 'usage: detection.py PART [its flags]', '']
    lines += ['  %-10s bench/%s.py: %s' % (part, module, what) for part, (module, what) in PARTS.items()]
    return '\n'.join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ('-h', '--help'):
        print(usage())
        return 0
    if argv[0] not in PARTS:
        print('part: %s is not one of %s' % (argv[0], ', '.join(PARTS)), file=sys.stderr)
        return 2
    module = importlib.import_module(PARTS[argv[0]][0])
    sys.argv = [os.path.join('bench', module.__name__ + '.py')] + argv[1:]  # the part's --help names itself
    return module.main(argv[1:])


if __name__ == '__main__':
    sys.exit(main())
