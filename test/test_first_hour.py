"""
The README's first hour on a real ROS 2 install, command by command (apt installs aside).

A fresh ``git clone`` of this repository into ``ws/src/imu_allan``, ``colcon build
--packages-select imu_allan`` in ``ws``, then in a shell that ran ``source install/setup.bash``:
the package is found the way ``ros2 run`` finds it, and ``analyze my_bag/ --out report/``
writes its report.  (The rosdep lines: test_package_deps.py; ``ros2 launch``: test_launch.py.)
"""

from pathlib import Path
import shutil
import subprocess
import sys

from conftest import REPO
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros


def run(cmd, cwd, timeout=300):
    """Run a shell line the way the README gives it; fail with its output."""
    proc = subprocess.run(['bash', '-c', cmd], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, f'{cmd}\n{proc.stdout}\n{proc.stderr}'
    return proc.stdout


@pytest.mark.slow
def test_clone_build_source_run(tmp_path):
    """Clone, colcon build, source, then ``ros2 run imu_allan analyze`` on a bag."""
    if not (REPO / '.git').exists() or shutil.which('git') is None:
        pytest.skip('not a git checkout')
    ws = tmp_path / 'ros2_ws'
    (ws / 'src').mkdir(parents=True)
    run(f'git clone --quiet {REPO} imu_allan', ws / 'src')
    colcon = Path(sys.executable).parent / 'colcon'
    run(f'{colcon} build --packages-select imu_allan --event-handlers console_cohesion- '
        f'summary-', ws)

    bag = tmp_path / 'my_bag'
    data = simulate(thesis_gx3_25_model(), 60000, 100.0, seed=4)  # 10 min at 100 Hz
    write_imu_bag(bag, Samples(t=1.7e9 + np.arange(data.shape[0]) / 100.0, data=data))
    # `ros2 run PKG EXE` = the ament index prefix of PKG + lib/PKG/EXE (ros2run's lookup)
    code = ('import sys; from ament_index_python.packages import get_package_prefix; '
            'print(get_package_prefix(sys.argv[1]))')
    lookup = f'$(python -c "{code}" imu_allan)/lib/imu_allan/analyze'
    out = run(f'source install/setup.bash && echo "$AMENT_PREFIX_PATH" && '
              f'{lookup} {bag} --out {tmp_path / "report"}', ws)
    assert out.splitlines()[0].startswith(str(ws / 'install' / 'imu_allan')), out
    assert 'white_noise' in out
    assert (tmp_path / 'report' / 'report.json').is_file()
    assert (tmp_path / 'report' / 'imu.yaml').is_file()
