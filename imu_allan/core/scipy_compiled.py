"""
scipy's compiled routines without the import cost of the subpackages around them.

A one-minute ``analyze`` needs two compiled routines of scipy: the NNLS of
``scipy.optimize`` and the inverse incomplete gamma function of ``scipy.special`` (chi-square
quantiles).  Importing those subpackages takes 0.3 s each on the benchmark machine (their array
API layers, linear programming, ...), a third of the whole command, for two functions that
load in milliseconds.  :func:`extension` loads one compiled module from its file inside the
installed scipy without running its subpackage's ``__init__``; it returns None when the module
is not there (another scipy layout), and callers then use the public function.
``requirements.txt`` pins the scipy version; tests compare each direct routine with its
public counterpart.
"""

import functools
import importlib
import importlib.machinery
import importlib.util
import os


@functools.cache
def extension(subpackage, name):
    """
    Return scipy's compiled module ``scipy.<subpackage>.<name>``, loaded on its own, or None.

    CPython enters it in ``sys.modules`` under that name, so a later ``import
    scipy.<subpackage>`` uses this module rather than loading it again.
    """
    qualified = f'scipy.{subpackage}.{name}'
    try:
        scipy_spec = importlib.util.find_spec('scipy')  # finds the package, does not run it
    except (ImportError, ValueError):
        return None
    if scipy_spec is None:
        return None
    for root in scipy_spec.submodule_search_locations or []:
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(root, subpackage, name + suffix)
            if not os.path.isfile(path):
                continue
            loader = importlib.machinery.ExtensionFileLoader(qualified, path)
            spec = importlib.util.spec_from_file_location(qualified, path, loader=loader)
            try:
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
            except ImportError:  # it needs its package after all
                return None
            return module
    return None


def function(subpackage, name, attribute):
    """
    Return ``attribute`` of the compiled module, or the public ``scipy.<subpackage>`` one.

    For routines whose compiled and public forms take the same arguments (ufuncs).
    """
    module = extension(subpackage, name)
    if module is not None and hasattr(module, attribute):
        return getattr(module, attribute)
    return getattr(importlib.import_module(f'scipy.{subpackage}'), attribute)
