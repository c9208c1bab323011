"""
Module dependencies that must point one way (issue 26): no pair imports each other.

Read from the source with ``ast`` (module-level and function-level imports alike: a lazy
import inside a function is still a dependency), so the test fails the moment a back edge
returns, whichever import style it uses.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'imu_allan'

#: (module, module it must not import) - the second depends on the first, never back.
ONE_WAY = [
    ('formats/imu_adapter.py', 'imu_allan.formats.imu_cdr'),
    ('cli/batch.py', 'imu_allan.cli.analyze'),
    ('cli/one_input.py', 'imu_allan.cli.analyze'),
    ('cli/one_input.py', 'imu_allan.cli.batch'),
]


def imported_modules(rel):
    """Absolute names of every module a source file imports (relative imports resolved)."""
    path = PACKAGE / rel
    package = ['imu_allan', *Path(rel).parent.parts]
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            mod = '.'.join(base + ([node.module] if node.module else []))
            names.add(mod)
            names.update(f'{mod}.{a.name}' for a in node.names)
    return names


@pytest.mark.parametrize('rel, forbidden', ONE_WAY)
def test_dependency_points_one_way(rel, forbidden):
    """The module does not import the one that depends on it."""
    assert forbidden not in imported_modules(rel)


def test_the_other_direction_is_real():
    """The checks look at real edges: the dependent modules do import the ones above."""
    assert 'imu_allan.formats.imu_adapter' in imported_modules('formats/imu_cdr.py')
    assert 'imu_allan.cli.one_input' in imported_modules('cli/batch.py')
    assert 'imu_allan.cli.batch' in imported_modules('cli/analyze.py')
