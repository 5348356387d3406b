"""Learn mode (``rosrun cc_log learn.py``; no roscore): train on one directory of feature vectors,
validate on a disjoint one, print the report, save the model.

    learn.py --train DIR [--validate DIR] --model PATH [--nu NU] [--gamma GAMMA] [--method auto|exact|nystroem]

Both directories hold ``<label>/<stamp>.json`` vector files (written by collect mode or ``cclog collect``).
The label ``nominal`` is normal behaviour; every other label (``anomalous``, ``collision``, ...) is
anomalous. Training needs nominal vectors; anomalous ones there, when present, tune ``nu``, ``gamma`` and
the threshold for full recall. The validation directory (optional: without it the model is trained and saved
unvalidated) must not be, contain or lie inside the training one, and may not share a single vector with it.

Pure (no rospy); ``cclog learn`` calls ``learn`` and ``format_result`` too.
"""
import argparse
import os
import sys

import numpy as np

from cc_log.learning import learning

NOMINAL = 'nominal'
DEFAULT_METHOD = 'auto'


def split_labels(vectors):
    """``(nominal, anomalous)`` 2-D arrays (anomalous: every label but 'nominal'; None when absent)."""
    nominal = vectors.get(NOMINAL)
    others = [array for label, array in sorted(vectors.items()) if label != NOMINAL]
    anomalous = np.concatenate(others) if others else None
    return nominal, anomalous


def check_disjoint(train_dir, validate_dir, train_vectors, validate_vectors):
    """Raise ValueError('validate: ...') unless the two sets are apart, as directories and as data."""
    train_real = os.path.realpath(train_dir)
    validate_real = os.path.realpath(validate_dir)
    if train_real == validate_real:
        raise ValueError('validate: %s is the training directory' % validate_dir)
    for inner, outer in ((validate_real, train_real), (train_real, validate_real)):
        if inner.startswith(outer.rstrip(os.sep) + os.sep):
            raise ValueError('validate: %s and %s overlap (one lies inside the other)' % (validate_dir, train_dir))
    seen = set()
    for array in train_vectors.values():
        seen.update(row.tobytes() for row in np.ascontiguousarray(array))
    shared = sum(1 for array in validate_vectors.values() for row in np.ascontiguousarray(array)
                 if row.tobytes() in seen)
    if shared:
        raise ValueError('validate: %d vector(s) of %s are also in %s' % (shared, validate_dir, train_dir))


def _save(model, model_path):
    try:
        model.save(model_path)
    except OSError as error:
        raise ValueError('model: cannot write %s: %s' % (model_path, error.strerror or error))


def learn(train_dir, validate_dir, model_path, nu=None, gamma=None, method=DEFAULT_METHOD, trim=learning.DEFAULT_TRIM):
    """Train on ``train_dir`` and save to ``model_path``, validate on ``validate_dir``; either may be None
    (train only; or evaluate the model at ``model_path``). Returns ``(model, report or None, info)``; raises
    ValueError('<what>: ...')."""
    from cc_log.learning.model import AnomalyModel
    if train_dir is None and validate_dir is None:
        raise ValueError('train: give a directory to train on, one to validate on, or both')
    if not model_path:
        raise ValueError('model: the output path is required')
    for name, directory in (('train', train_dir), ('validate', validate_dir)):
        if directory is not None and not os.path.isdir(directory):
            raise ValueError('%s: %s: no such directory of feature vectors' % (name, directory))
    if train_dir is None:
        model = AnomalyModel.load(model_path)  # a bad model file is named before any vector is read
        validate_vectors, validate_config = learning.load_vectors(validate_dir)
        model.check_config(validate_config)
        return model, learning.evaluate(model, *split_labels(validate_vectors)), {}
    validate_vectors, validate_config = learning.load_vectors(validate_dir) if validate_dir else (None, None)
    folder = os.path.dirname(os.path.abspath(model_path))
    if not os.path.isdir(folder):
        raise ValueError('model: directory %s does not exist' % folder)
    train_vectors, config, stamps = learning.load_vectors(train_dir, with_stamps=True)
    if validate_dir is not None:
        if validate_config != config:
            raise ValueError('validate: vectors of %s were computed with %s, the training ones with %s'
                             % (validate_dir, validate_config.to_dict(), config.to_dict()))
        check_disjoint(train_dir, validate_dir, train_vectors, validate_vectors)
    nominal, anomalous = split_labels(train_vectors)
    if nominal is None:
        raise ValueError('train: %s has no %s/ vectors' % (train_dir, NOMINAL))
    model, info = learning.train(nominal, anomalous, config, nu=nu, gamma=gamma, method=method, trim=trim,
                                 stamps=stamps[NOMINAL])
    report = learning.evaluate(model, *split_labels(validate_vectors)) if validate_dir is not None else None
    _save(model, model_path)
    return model, report, dict(info, model=model_path, train=train_dir, validate=validate_dir)


def format_result(model, report, info):
    """The printed result: the paper's table (or that nothing was validated), then where the model went."""
    table = learning.format_report(report, info) if report is not None else \
        '%-16s %s' % ('Validated', 'no (--validate DIR validates on a disjoint set)')
    return '%s\n%-16s %s (%s features, window %s)' % (
        table, 'Saved', info['model'], model.config.feature_set,
        model.config.window)


def parse_args(argv):
    parser = argparse.ArgumentParser(
        prog='learn.py', description='Learn mode: train the anomaly model on one directory of feature vectors, '
        'validate it on a disjoint one, print the report and save the model.')
    parser.add_argument('--train', required=True, metavar='DIR', help='training vectors (<label>/<stamp>.json)')
    parser.add_argument('--validate', metavar='DIR', help='validation vectors, disjoint from --train (optional)')
    parser.add_argument('--model', required=True, metavar='PATH', help='where to save the model (JSON)')
    parser.add_argument('--nu', type=float, default=None, help='one-class SVM nu (default: %g, or a grid search '
                        'when the training directory has anomalous vectors)' % learning.DEFAULT_NU)
    parser.add_argument('--gamma', type=float, default=None, help='RBF gamma on standardised vectors '
                        '(default: %g / n_features, or a grid search)' % learning.DEFAULT_GAMMA_FACTOR)
    parser.add_argument('--method', choices=learning.METHODS, default=DEFAULT_METHOD,
                        help='exact one-class SVM, Nystroem + SGD, or auto (default: %(default)s)')
    # roslaunch/rosrun add remapping arguments (name:=value) and __name/__log: not ours.
    return parser.parse_args([arg for arg in argv if ':=' not in arg])


def main(argv=None):
    """Run learn mode; return the exit status: 1 with one line on stderr for bad input (2 for a bad command
    line, from argparse)."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        model, report, info = learn(args.train, args.validate, args.model, args.nu, args.gamma, args.method)
    except ValueError as error:
        sys.stderr.write('learn: %s\n' % error)
        return 1
    print(format_result(model, report, info))
    return 0
