"""The simulated device's temperature: profile, bias slope, 0xD1 answers, options."""

import subprocess
import sys

from imu_allan.core.model import NoiseModel
from imu_allan.device import gx3_protocol as p
from imu_allan.device.simulator import Device, NoiseSource, SimConfig
import numpy as np
import pytest


def device(**options):
    """Return a noise-free simulated unit (empty noise model), powered up at 100 s."""
    cfg = SimConfig(gravity_axis='none', **options)
    cfg.check()
    return Device(cfg, NoiseSource(NoiseModel({}), 0), 100.0)


def test_bias_follows_the_profile_with_the_slope():
    """Noise-free records: gyro = slope * (T - T0) exactly (float32), accel in g."""
    dev = device(temperature='ramp:20:40:10', temperature_slope='1e-3,-2e-3,0,0.01,0,0')
    for t in (0.0, 2.5, 5.0, 20.0):
        _, truth = dev.make_record(0xC2, 0, 100.0 + t)
        celsius = min(20.0 + 2.0 * t, 40.0)
        assert truth['temperature_c'] == pytest.approx(celsius)
        shift = np.array([1e-3, -2e-3, 0.0]) * (celsius - 20.0)
        assert truth['gyro'] == [float(v) for v in shift.astype(np.float32)]
        assert truth['accel'][0] == pytest.approx(0.01 * (celsius - 20.0) / 9.80665, rel=1e-6)


def test_d1_answers_idle_and_while_streaming():
    """Idle: answered at once; streaming: held for the next record (no reply now)."""
    dev = device(temperature='warmup:20:45:300')
    reply = dev.feed(p.cmd_temperatures(), 100.0 + 300.0)[0]
    got = p.decode_temperature_reply(reply)
    assert got.celsius == pytest.approx(45 - 25 / np.e, abs=0.07)   # one ADC code
    assert got.timer == 300 * p.TICKS_PER_SECOND
    assert got.counts[1] - got.counts[0] == 40
    dev.start_stream(0xC2, 500.0)
    assert dev.feed(p.cmd_temperatures(), 500.001) == []
    assert dev.temperature_polls == 1


def test_bad_temperature_options():
    """Bad profile or slope: ValueError naming the option; the command exits 2, one line."""
    with pytest.raises(ValueError, match='--temperature '):
        SimConfig(temperature='hot').check()
    with pytest.raises(ValueError, match='--temperature-slope'):
        SimConfig(temperature_slope='1,2').check()
    with pytest.raises(ValueError, match='--temperature-slope'):
        SimConfig(temperature_slope='1e-3,x,0').check()
    out = subprocess.run([sys.executable, '-m', 'imu_allan.cli.gx3_sim', '--temperature',
                          'ramp:20:40'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr.count('\n') == 1
    assert '--temperature' in out.stderr
