"""learn.py: --validate is optional (train and save; the report says nothing was validated)."""
import numpy as np

from cc_log.offline import learn_main
from cc_log.learning import learning
from cc_log.features import FeatureConfig
from cc_log.learning.model import AnomalyModel


def test_learn_without_validation_trains_and_saves(tmp_path, capsys):
    config = FeatureConfig('motion', '20')
    rows = np.random.default_rng(3).normal(size=(200, 72))  # the motion set has 72 features
    for index, row in enumerate(rows):
        learning.write_vector(str(tmp_path / 'train'), 'nominal', 1000.0 + index, row, config)
    model_path = str(tmp_path / 'model.json')
    status = learn_main.main(['--train', str(tmp_path / 'train'), '--model', model_path, '__name:=learn'])
    out = capsys.readouterr().out
    assert status == 0 and AnomalyModel.load(model_path).config == config
    assert 'Validated        no' in out and model_path in out and 'Precision' not in out
