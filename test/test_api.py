"""The public Python API: every advertised name loads, nothing changes the environment."""

import json
import subprocess
import sys

from conftest import REPO


def test_every_public_name_loads_without_side_effects():
    """Import imu_allan + every name in __all__: no environment variable set or changed."""
    code = ('import json, os; before = dict(os.environ); import imu_allan; '
            'names = [n for n in imu_allan.__all__ if getattr(imu_allan, n) is None]; '
            'print(json.dumps({"same_env": dict(os.environ) == before, "none": names, '
            '"version": imu_allan.__version__}))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120, env={'PATH': '/usr/bin:/bin', **_pythonpath()})
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result['same_env'] and result['none'] == []
    xml = (REPO / 'package.xml').read_text()
    assert f'<version>{result["version"]}</version>' in xml


def test_api_names_cover_the_contract():
    """The names docs/interfaces.md promises are in __all__."""
    import imu_allan
    for name in ('allan_deviation', 'fit_noise_model', 'simulate', 'NoiseModel',
                 'thesis_gx3_25_model', 'StreamingAllan', 'OnlineAllan', 'read_samples',
                 'denoise', 'run_discrepancy', 'edf_oadev', 'chi2_interval', '__version__'):
        assert name in imu_allan.__all__, name


def _pythonpath():
    import os
    return {k: v for k, v in os.environ.items() if k in ('PYTHONPATH', 'HOME')}
