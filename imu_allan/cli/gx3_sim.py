"""
gx3_sim: a simulated LORD MicroStrain 3DM-GX3-25 on a pseudo-terminal.

Prints the path a driver should open as its first stdout line, then behaves like a 3DM-GX3-25
with single-byte firmware (the DCP manual, docs/references.md): it answers the commands and
streams continuous mode at 1000 Hz / decimation, paced by the baud rate, with the noise
model's samples through the device's own processing.  docs/driver.md (section gx3_sim)
describes the values sent, the fault injection, the temperature profile and the truth CSV;
``--help`` the options and their units.

Choices where the DCP manual is silent: unknown command bytes and a bare
``FA`` are ignored; an invalid continuous-command byte is ignored and the current one echoed;
the 0xC4 reply precedes the first record; the device powers up in Active mode (or streaming,
with ``--stream``); polled data commands are answered at once; 0xCD replies after at most
``--max-bias-delay`` seconds.  Records are paced per record: one whose bytes cannot leave
before the next record is due (baud too low for the rate) is not sent, as a UART overrun
would lose it; its timer value is skipped, so the host sees a gap.  The pty's settings are
shared by both ends, so the simulator sees the baud rate the host opened the port at: at a
rate other than the device's it ignores what the host sends and the host receives garbage,
as with a real UART (``--ignore-host-baud`` turns this off).  0xD1 polled while streaming is
answered after the next record, with its timer (the order the manual gives for the GX2).
"""

import dataclasses
import signal
import sys

from .common import ArgumentParser, bounded_float, bounded_int, guarded
from ..core.model import NoiseModel, thesis_gx3_25_model
from ..core.units import STANDARD_GRAVITY
from ..device import gx3_protocol as p
from ..device.simulator import ID_STRINGS, SimConfig, Simulator
from ..errors import InputError


def build_parser():
    """Command-line parser of gx3_sim."""
    ap = ArgumentParser(prog='gx3_sim', description='Simulated 3DM-GX3-25 on a pseudo-terminal.')
    ap.add_argument('--model', help='noise model YAML file (default: thesis 3DM-GX3-25 values)')
    ap.add_argument('--gravity-axis', default='-z',
                    help='axis that reads 1 g: x, y, z, -x, -y, -z or none (default -z)')
    ap.add_argument('--gravity', type=bounded_float(0.0, 100.0, low_open=True),
                    default=STANDARD_GRAVITY,
                    help='m/s^2 per g used to express the noise in g (default 9.80665)')
    ap.add_argument('--rate-hz', type=bounded_float(0.0, 1000.0, low_open=True), default=100.0,
                    help='power-up data rate, Hz (decimation = 1000/rate; default 100)')
    ap.add_argument('--baud', type=bounded_int(300, 10**7), default=p.DEFAULT_BAUD,
                    help='power-up baud rate used for pacing (default 115200)')
    ap.add_argument('--stream', default=None,
                    help='power up streaming this data command (hex, e.g. C2)')
    ap.add_argument('--timer-start', type=bounded_int(0, 2**32 - 1), default=0,
                    help='device timer at power-up, ticks (e.g. 4294900000 to test rollover)')
    ap.add_argument('--seed', type=bounded_int(0, 2**63 - 1), default=None, help='random seed')
    ap.add_argument('--link', help='also make this symlink to the terminal (stable path)')
    ap.add_argument('--record-truth', metavar='FILE', help='CSV of every record sent')
    ap.add_argument('--duration', type=bounded_float(0.0, 1e7), default=None,
                    help='exit after this many s')
    ap.add_argument('--firmware', type=bounded_int(0, 2**31 - 1), default=1130,
                    help='firmware number (1130)')
    ap.add_argument('--serial', default=ID_STRINGS[1], help='serial number string')
    ap.add_argument('--ignore-host-baud', action='store_true',
                    help='talk to the host whatever baud rate it opened the port at')
    ap.add_argument('--max-bias-delay', type=bounded_float(0.0, 60.0), default=0.2,
                    help='cap on the 0xCD gyro-bias capture delay, s (default 0.2)')
    ap.add_argument('--corrupt-rate', type=bounded_float(0.0, 1.0), default=0.0,
                    help='probability that a record gets one data byte flipped')
    ap.add_argument('--drop-rate', type=bounded_float(0.0, 1.0), default=0.0,
                    help='probability that a record is not sent')
    ap.add_argument('--garbage-rate', type=bounded_float(0.0, 1.0), default=0.0,
                    help='probability of a burst of 1..32 junk bytes before a record')
    ap.add_argument('--stall-after', type=bounded_float(0.0, 1e7), default=None,
                    help='seconds of streaming before the device goes silent')
    ap.add_argument('--stall-seconds', type=bounded_float(0.0, 3600.0), default=2.0,
                    help='length of the stall, s (default 2)')
    ap.add_argument('--disconnect-after', type=bounded_float(0.0, 1e7), default=None,
                    help='seconds of streaming before the terminal is closed')
    ap.add_argument('--disconnect-seconds', type=bounded_float(0.0, 3600.0), default=1.0,
                    help='time before the device comes back, s (default 1)')
    ap.add_argument('--temperature', default='constant:25', metavar='PROFILE',
                    help='board temperature against time since start, deg C: constant:T, '
                         'ramp:T0:T1:SECONDS or warmup:T0:T1:TAU (default constant:25)')
    ap.add_argument('--temperature-slope', metavar='GX,GY,GZ[,AX,AY,AZ]',
                    help='bias change per K of temperature above the profile start: gyro '
                         'rad/s/K (then accel m/s^2/K); default none')
    return ap


def _terminate(signum, frame):
    raise SystemExit(0)


@guarded
def main(argv=None):
    """Entry point of ``gx3_sim``."""
    args = build_parser().parse_args(argv)
    options = {f.name: getattr(args, f.name) for f in dataclasses.fields(SimConfig)}
    config = SimConfig(**options)
    try:
        config.check()
    except ValueError as exc:
        raise InputError(*str(exc).split(' ', 1)) from None
    model = NoiseModel.from_yaml(args.model) if args.model else thesis_gx3_25_model()
    signal.signal(signal.SIGTERM, _terminate)
    sim = Simulator(model, config=config)
    try:
        sim.run()
    except KeyboardInterrupt:
        pass
    finally:
        sim.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
