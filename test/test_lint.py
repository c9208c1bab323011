"""Lint as ROS packages do (ament_flake8 + ament_pep257 rules, via ruff; see ruff.toml)."""

from pathlib import Path
import subprocess
import sys

from conftest import REPO


def test_ruff_flake8_and_pep257_rules():
    ruff = Path(sys.executable).parent / 'ruff'
    paths = ['imu_allan', 'test', 'scripts', 'bench', 'launch', 'setup.py']
    proc = subprocess.run([str(ruff), 'check', '--no-cache', *paths], cwd=REPO,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
