"""ament_pep257 with ament's own configuration, as ament_python packages run it."""

from ament_pep257.main import main
from conftest import REPO
import pytest
from test_flake8 import PATHS


@pytest.mark.slow
@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    rc = main(argv=[str(REPO / p) for p in PATHS])
    assert rc == 0, 'Found code style errors / warnings'
