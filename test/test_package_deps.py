"""
Every dependency is declared in package.xml, with a rosdep key that resolves.

The real ``rosdep`` tool (PyPI package, pinned below, in a throwaway venv under ``build/``
made once per machine) runs offline against the rosdistro snapshot in the shared data folder
plus this repository's ``rosdep.yaml``, as a user's ``rosdep install --from-paths src`` would.
"""

import ast
import os
import subprocess
import sys

from catkin_pkg.package import parse_package
from conftest import REPO, SHARED_DATA
import pytest

ROSDEP_VERSION = '0.27.0'
ROSDEP_DB = SHARED_DATA / 'rosdep'

#: Imported top-level module -> the package.xml key that provides it.  Modules of the Python
#: standard library need none.  lz4 and backports.zstd come with rosbags (its requirements).
MODULE_KEYS = {
    'rclpy': 'rclpy', 'rcl_interfaces': 'rcl_interfaces', 'sensor_msgs': 'sensor_msgs',
    'std_msgs': 'std_msgs', 'diagnostic_msgs': 'diagnostic_msgs',
    'ament_index_python': 'ament_index_python', 'launch': 'launch', 'launch_ros': 'launch_ros',
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'numba': 'python3-numba',
    'serial': 'python3-serial', 'pywt': 'python3-pywt', 'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib', 'rosbags': 'python3-rosbags-pip',
    'jinja2': 'python3-jinja2', 'markupsafe': 'python3-jinja2',
    'lz4': 'python3-rosbags-pip', 'backports': 'python3-rosbags-pip',
    'setuptools': 'python3-setuptools', 'gtsam': 'python3-gtsam-pip',
}


def required_imports(path):
    """
    Return the top-level modules a file imports.

    Except optional ones (inside ``try: ... except ImportError``) and relative imports.
    """
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    optional = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(
                isinstance(h.type, ast.Name) and h.type.id in ('ImportError',
                                                               'ModuleNotFoundError')
                for h in node.handlers):
            for stmt in node.body:
                optional.update(id(n) for n in ast.walk(stmt))
    found = set()
    for node in ast.walk(tree):
        if id(node) in optional:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name.split('.')[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            found.add(node.module.split('.')[0])
    return found - set(sys.stdlib_module_names) - {'imu_allan'}


def test_every_import_is_declared():
    """Modules imported in imu_allan/ and launch/ are exec_depends, setup.py's build_depends."""
    pkg = parse_package(str(REPO / 'package.xml'))
    exec_keys = {d.name for d in pkg.exec_depends}
    build_keys = {d.name for d in pkg.build_depends}
    sources = sorted((REPO / 'imu_allan').rglob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
    missing = []
    for path in sources:
        for module in sorted(required_imports(path)):
            key = MODULE_KEYS.get(module)
            if key is None or key not in exec_keys:
                missing.append(f'{path.relative_to(REPO)}: {module} -> {key or "no key known"}')
    for module in required_imports(REPO / 'setup.py'):
        if MODULE_KEYS.get(module) not in build_keys:
            missing.append(f'setup.py: {module} is not a build_depend')
    assert not missing, 'imported but not declared in package.xml:\n' + '\n'.join(missing)


def test_optional_imports_are_recognised(tmp_path):
    """The guard rule: an import inside ``try/except ImportError`` is optional, others not."""
    source = tmp_path / 'm.py'
    source.write_text('import os\nimport numpy\ntry:\n    import numba\nexcept ImportError:\n'
                      '    numba = None\ntry:\n    import pywt\nexcept ValueError:\n    pass\n')
    assert required_imports(source) == {'numpy', 'pywt'}


@pytest.fixture(scope='session')
def rosdep(shared_data):
    """Run the pinned rosdep offline against the snapshot + rosdep.yaml (a function of args)."""
    if not (ROSDEP_DB / 'index-v4.yaml').is_file():
        pytest.skip(f'{ROSDEP_DB} not present')
    venv = REPO / 'build' / 'rosdep-venv'
    stamp = venv / 'rosdep-version'
    if not (stamp.is_file() and stamp.read_text() == ROSDEP_VERSION):
        # The base interpreter, not this venv's: its ROS wheels' start-up hook is not wanted.
        base = getattr(sys, '_base_executable', sys.executable)
        subprocess.run([base, '-m', 'venv', '--clear', str(venv)], check=True)
        pip = subprocess.run([str(venv / 'bin' / 'python'), '-m', 'pip', 'install', '--quiet',
                              f'rosdep=={ROSDEP_VERSION}'], capture_output=True, text=True)
        assert pip.returncode == 0, pip.stderr
        stamp.write_text(ROSDEP_VERSION)
    work = REPO / 'build' / 'rosdep-home'
    sources = work / 'sources.list.d'
    sources.mkdir(parents=True, exist_ok=True)
    db = ROSDEP_DB.resolve()
    (sources / '20-default.list').write_text(
        f'yaml file://{db}/rosdep/base.yaml\nyaml file://{db}/rosdep/python.yaml\n'
        f'yaml file://{REPO / "rosdep.yaml"}\n')
    env = dict(os.environ, ROSDISTRO_INDEX_URL=f'file://{db}/index-v4.yaml',
               ROSDEP_SOURCE_PATH=str(sources), ROS_HOME=str(work / 'home'),
               ROS_DISTRO='jazzy', ROS_PYTHON_VERSION='3', ROS_OS_OVERRIDE='ubuntu:24.04:noble')
    # Not this environment's ROS prefixes or pip: rosdep would skip the keys they satisfy.
    for name in ('PYTHONPATH', 'AMENT_PREFIX_PATH', 'VIRTUAL_ENV'):
        env.pop(name, None)
    env['PATH'] = f'{venv / "bin"}:/usr/bin:/bin'

    def run(*args, os_override=None):
        run_env = dict(env, ROS_OS_OVERRIDE=os_override) if os_override else env
        return subprocess.run([str(venv / 'bin' / 'rosdep'), *args], cwd=REPO, env=run_env,
                              capture_output=True, text=True, timeout=120)
    update = run('update')
    assert update.returncode == 0, update.stdout + update.stderr
    return run


@pytest.mark.slow
def test_rosdep_resolves_every_key(rosdep):
    """
    ``rosdep install --simulate`` finds a rule for every key (exit 0, no unknown key).

    ``rosdep check`` says the same key by key, but also exits 1 because the apt packages are
    not installed on this machine, so its output is checked instead of its status.
    """
    install = rosdep('install', '--from-paths', '.', '--ignore-src', '--simulate',
                     '--default-yes')
    assert install.returncode == 0, install.stdout + install.stderr
    for line in ('apt-get install -y ros-jazzy-launch-ros', 'apt-get install -y python3-pywt',
                 'apt-get install -y python3-numba', 'pip3 install -U rosbags'):
        assert line in install.stdout, install.stdout
    check = rosdep('check', '--from-paths', '.', '--ignore-src', '--simulate')
    assert 'Cannot locate rosdep definition' not in check.stdout + check.stderr, check.stderr
    assert 'ERROR' not in check.stderr, check.stderr


def test_rosdep_yaml_has_a_pip_fallback(rosdep):
    """python3-pywt: the apt package on Ubuntu and Debian, PyWavelets from pip elsewhere."""
    for os_override, expected in (('ubuntu:24.04:noble', '#apt\npython3-pywt'),
                                  ('debian:12:bookworm', '#apt\npython3-pywt'),
                                  ('osx:14:sonoma', '#pip\nPyWavelets')):
        out = rosdep('resolve', 'python3-pywt', os_override=os_override)
        assert out.returncode == 0 and out.stdout.strip() == expected, (os_override, out)


def test_gtsam_test_dependency_resolves_to_pip(rosdep):
    """Resolve the GTSAM test dependency: its Python module from pip on every platform."""
    pkg = parse_package(str(REPO / 'package.xml'))
    assert 'python3-gtsam-pip' in {d.name for d in pkg.test_depends}
    for os_override in ('ubuntu:24.04:noble', 'debian:12:bookworm', 'osx:14:sonoma'):
        out = rosdep('resolve', 'python3-gtsam-pip', os_override=os_override)
        assert out.returncode == 0 and out.stdout.strip() == '#pip\ngtsam', (os_override, out)
