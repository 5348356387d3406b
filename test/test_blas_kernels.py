"""The tests whose floats go through BLAS in two ways, run again under OpenBLAS's Prescott kernel: it rounds each
matrix shape and memory alignment its own way (a batch of vectors against one, in the last bits), so a plain run
on any CPU also checks that those floats are compared within ``approx_floats`` and the decisions made from them
exactly. By hand: ``OPENBLAS_CORETYPE=Prescott /usr/bin/python3 -m pytest -q test/...``."""
import os
import subprocess
import sys

import pytest

from conftest import ROOT

KERNEL = 'Prescott'
#: Tests comparing floats computed through BLAS in two shapes or at two places in memory.
BLAS_SENSITIVE = (
    'test/test_feature_batches.py',
    'test/test_batch_replay.py::test_scoring_a_batch_gives_each_vectors_own_score_and_decision',
    'test/test_online_learning.py::test_a_refit_only_widens_what_the_original_finds_nominal',
    'test/test_model.py::test_save_load_round_trip',
    'test/test_envelope.py::test_the_joint_ratio_is_the_detector_benchmarks_robust_mahalanobis_at_its_level',
    'test/test_envelope.py::test_the_trigger_scores_with_the_joint_check_alike_whatever_the_batches',
    'test/test_local_density.py::test_scores_are_scikit_learns_local_outlier_factor_and_decisions_match_at_every_level',
    'test/test_local_density.py::test_the_default_flags_exactly_what_the_benchmarks_env2_maha4_lof6_flags',
)
ARCHITECTURE = ('import numpy, threadpoolctl; print(" ".join(str(i.get("architecture")) '
                'for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"))')


def under_kernel(kernel, *args):
    """Run ``python3 ARGS`` in the repository with ``OPENBLAS_CORETYPE=kernel``; the CompletedProcess."""
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel)
    return subprocess.run([sys.executable] + list(args), cwd=ROOT, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, universal_newlines=True, timeout=600)


def test_the_blas_sensitive_tests_pass_under_the_prescott_kernel():
    kernels = under_kernel(KERNEL, '-c', ARCHITECTURE)
    assert kernels.returncode == 0, kernels.stdout
    if not kernels.stdout.split():
        pytest.skip('numpy does not use OpenBLAS here: OPENBLAS_CORETYPE chooses nothing')
    assert kernels.stdout.split() == [KERNEL], kernels.stdout  # the kernel asked for is the one numpy calls
    result = under_kernel(KERNEL, '-m', 'pytest', '-q', '-p', 'no:cacheprovider', *BLAS_SENSITIVE)
    assert result.returncode == 0, result.stdout[-4000:]
