"""ament_flake8 with ament's own configuration, as ament_python packages run it."""

import os

from ament_flake8.main import main_with_errors
from conftest import REPO
import pytest

#: The package's sources (what ``colcon test`` checks from the package folder, where the build,
#: install and venv folders of this checkout do not live).
PATHS = ['imu_allan', 'launch', 'test', 'scripts', 'bench', 'setup.py']


@pytest.mark.slow
@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        rc, errors = main_with_errors(argv=PATHS)
    finally:
        os.chdir(cwd)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
