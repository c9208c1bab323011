"""
Hostile model and budget files: one schema, one line naming the file, never a traceback.

Every command and node reads model files through ``NoiseModel.from_yaml`` and budget files
through ``NoiseBudget.from_yaml``; both validate against the schema of
:mod:`imu_allan.core.model`.  Each case runs in milliseconds.
"""

from imu_allan.core.live.health import NoiseBudget
from imu_allan.core.model import NoiseModel
from imu_allan.errors import InputError
import pytest

BAD = [
    ('gyro: 5\n', 'gyro must be a mapping'),
    ('axes: [gyro_x, gyro_y]\n', 'axes must be a mapping'),
    ('axes: {gyro_x: 5}\n', 'axes.gyro_x must be a mapping'),
    ('gyro: {white_noise: 1.0e+300}\n', 'at most'),
    ('gyro: {white_noise: ' + '9' * 400 + '}\n', 'too large'),
    ('[' * 5000 + ']' * 5000 + '\n', 'nested too deeply'),
    ('gyro: {white_noise: true}\n', 'must be a number, not true/false'),
    ('gyro: {white_noise: .nan}\n', 'must be finite'),
    ('gyro: {white_noise: [1, 2]}\n', 'must be a number, not a list'),
    ('gyro: {white_noise: 1.0e-4}\ngyro: {white_noise: 2.0e-4}\n', "duplicate key 'gyro'"),
    ('gyro: {white_noise: 1.0e-4, white_noise: 2.0e-4}\n', "duplicate key 'white_noise'"),
    ('{1: 2}\n', 'unknown key(s) 1'),
    ('"just text"\n', 'expected a mapping'),
]
MODEL_ONLY = [
    ('rate_hz: 0\ngyro: {white_noise: 1.0e-4}\n', 'rate_hz = 0: must be a positive number'),
    ('rate_hz: -100\ngyro: {white_noise: 1.0e-4}\n', 'rate_hz = -100'),
    ('rate_hz: 100.0\naxes: {gyro_z: {sinusoid: {amplitude: 1.0e-4, frequency_hz: 80}}}\n',
     'not below the Nyquist frequency 50 Hz'),
    ('axes: {gyro_x: {gauss_markov: 5}}\n', 'gyro_x.gauss_markov must be a mapping'),
    ('axes: {gyro_x: {gauss_markov: {sigma: 1.0e-4}}}\n', 'needs sigma, tau_c'),
]


def _load(reader, tmp_path, content):
    path = tmp_path / 'file.yaml'
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(InputError) as info:
        reader(path)
    text = str(info.value)
    assert text.startswith(f'{path}: ') and '\n' not in text, text
    return text


@pytest.mark.parametrize('reader', [NoiseModel.from_yaml, NoiseBudget.from_yaml])
@pytest.mark.parametrize('content, problem', BAD)
def test_malformed_file_is_one_line_naming_the_file(tmp_path, reader, content, problem):
    """Malformed structure, absurd or non-numeric values, duplicate keys, deep nesting."""
    assert problem in _load(reader, tmp_path, content)


@pytest.mark.parametrize('content, problem', MODEL_ONLY)
def test_model_values_checked_against_the_rate(tmp_path, content, problem):
    """rate_hz must be positive; a sinusoid must lie below the Nyquist frequency."""
    assert problem in _load(NoiseModel.from_yaml, tmp_path, content)


@pytest.mark.parametrize('reader, what', [(NoiseModel.from_yaml, 'model'),
                                          (NoiseBudget.from_yaml, 'budget')])
def test_binary_special_and_huge_files(tmp_path, reader, what):
    """A binary file, a device, a folder and a huge file are refused without reading them whole."""
    assert f'binary data, not a {what} file' in _load(reader, tmp_path, b'\x89PNG\x00\x01' * 9)
    assert 'not UTF-8' in _load(reader, tmp_path, b'\xff\xfe gyro')
    for special, problem in (('/dev/zero', 'not a regular file'), (tmp_path, 'a directory')):
        with pytest.raises(InputError, match=problem):
            reader(special)
    big = tmp_path / 'big.yaml'
    big.write_text('# padding\n' * 200_000)
    with pytest.raises(InputError, match='larger than'):
        reader(big)


def test_valid_model_numbers_from_text_still_read(tmp_path):
    """YAML 1.1 reads ``1e-4`` as text; such numbers stay accepted (as before the schema)."""
    path = tmp_path / 'm.yaml'
    path.write_text('rate_hz: 100\ngyro: {white_noise: 1e-4}\n'
                    'axes: {gyro_z: {sinusoid: {amplitude: 1e-4, frequency_hz: 0.5}}}\n')
    model = NoiseModel.from_yaml(path)
    assert model.value('gyro_x', 'white_noise') == 1e-4 and model.rate_hz == 100.0
    assert model.value('gyro_z', 'sinusoid', 'frequency_hz') == 0.5
