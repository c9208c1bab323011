"""
Bit flips in the shared real bags: never a silent change where a strict reader sees damage.

Each shared bag (the converted Jackal MCAP and sqlite3 bags, the two ROS 1 bags) is copied
with seeded bit flips (:func:`flipped`: 20 per copy by default) and read by ``read_bag``; the
copy's *outcome* is ``same`` (the samples of the intact bag), ``warned`` (other samples, with a
warning), ``refused`` (one-line InputError) or ``silent`` (other samples, no warning).  An
independent strict reader judges the same copy (:func:`strict_problems`):

* MCAP: the ``mcap`` package (foxglove's reference reader, 1.6.0): every record through its
  non-seeking reader with CRC validation (it refuses a message on an undeclared channel, a
  channel on an undeclared schema, any record it cannot parse), the indexed reader, and the
  Statistics record's message count against the messages it reads.  The package is not a
  dependency of imu_allan: give the interpreter of a venv that has it (``--mcap-python``);
  without it the MCAP rows say so;
* sqlite3: SQLite's own ``PRAGMA integrity_check`` (:func:`.test_hostile_sqlite.integrity`);
* ROS 1: ``rosbags.rosbag1.Reader`` (header fields, chunk and index records), every message
  read, and the count against the bag's own connection counts.

The rule measured: no ``silent`` copy the strict reader calls damaged.  (A ``silent`` copy it
calls intact is a flipped value inside a message, which no reader can see in storage without
checksums.)  ``python test/formats/flip_cases.py [COPIES] [--flips K] [--mcap-python PY]``
prints the table of docs/analyze.md; the test (:mod:`.test_flip_cases`) runs a few copies.
"""

import json
import subprocess
import sys


def strict_mcap(paths):
    """
    Return {path: [problems]} of MCAP files from the ``mcap`` package (imported here only).

    Runs in any interpreter that has ``mcap``; needs nothing of imu_allan or numpy.
    """
    from mcap.reader import make_reader, NonSeekingReader
    out = {}
    for path in paths:
        problems = []
        try:
            with open(path, 'rb') as f:
                for _ in NonSeekingReader(f, validate_crcs=True).iter_messages(
                        log_time_order=False):
                    pass
        except Exception as exc:  # whatever it refuses is damage it sees
            problems.append(f'stream: {type(exc).__name__}: {exc}'[:160])
        try:
            with open(path, 'rb') as f:
                reader = make_reader(f, validate_crcs=True)
                summary = reader.get_summary()
                n = sum(1 for _ in reader.iter_messages(log_time_order=False))
                stats = summary.statistics if summary is not None else None
                if stats is not None and stats.message_count != n:
                    problems.append(f'Statistics counts {stats.message_count}, read {n}')
        except Exception as exc:
            problems.append(f'indexed: {type(exc).__name__}: {exc}'[:160])
        out[str(path)] = problems
    return out


def _strict_ros1(path):
    from rosbags.rosbag1 import Reader
    try:
        with Reader(path) as reader:
            n = sum(1 for _ in reader.messages())
            stated = sum(c.msgcount for c in reader.connections)
        return [] if n == stated else [f'connections count {stated}, read {n}']
    except Exception as exc:
        return [f'{type(exc).__name__}: {exc}'[:160]]


def strict_problems(storage, paths, mcap_python=None):
    """
    Return {path: [problems the strict reader reports]} (None for a path it could not judge).

    ``mcap_python``: an interpreter with the ``mcap`` package for MCAP files (default: this
    one, if it has it).
    """
    paths = [str(p) for p in paths]
    if storage == 'sqlite3':
        from formats.test_hostile_sqlite import integrity
        return {p: integrity(p) for p in paths}
    if storage == 'ros1':
        return {p: _strict_ros1(p) for p in paths}
    if mcap_python is None:
        try:
            return strict_mcap(paths)
        except ImportError:
            return dict.fromkeys(paths)
    run = subprocess.run([mcap_python, __file__, '--strict-mcap', *paths], capture_output=True,
                         text=True, check=True)
    return json.loads(run.stdout)


def flipped(raw, seed, flips=20):
    """Return ``raw`` with ``flips`` seeded single-bit flips at uniform positions."""
    import numpy as np
    rng = np.random.default_rng(seed)
    buf = bytearray(raw)
    for pos in rng.integers(0, len(buf), flips):
        buf[pos] ^= 1 << int(rng.integers(0, 8))
    return bytes(buf)


def outcome(path, ref):
    """Return 'same', 'warned', 'refused' or 'silent' of ``read_bag`` against ``ref``."""
    from imu_allan.errors import InputError
    from imu_allan.formats.bag_reader import read_bag
    import numpy as np
    try:
        got = read_bag(path)
    except InputError as exc:
        assert '\n' not in str(exc)
        return 'refused'
    if got.t.shape == ref.t.shape and np.array_equal(got.t, ref.t) and \
            np.array_equal(got.data, ref.data):
        return 'same'
    return 'warned' if got.warnings else 'silent'


#: The shared bags: (name, storage, path of the storage file under data/bags).
BAGS = (('jackal_test2_mcap', 'mcap', 'jackal_test2_mcap/jackal_test2_mcap.mcap'),
        ('jackal_test2_sqlite3', 'sqlite3', 'jackal_test2_sqlite3/jackal_test2_sqlite3.db3'),
        ('test1.bag', 'ros1', 'test1.bag'),
        ('test2.bag', 'ros1', 'test2.bag'))


def sweep(bags_dir, folder, seeds, flips=20, mcap_python=None, bags=BAGS):
    """
    Return {bag name: [(seed, outcome, strict problems)]} over the seeded copies.

    ``folder``: where the damaged copies are written (one per bag at a time).
    """
    from pathlib import Path

    from imu_allan.formats.bag_reader import read_bag
    out = {}
    for name, storage, rel in bags:
        src = Path(bags_dir) / rel
        raw, ref = src.read_bytes(), read_bag(src)
        paths = []
        for seed in seeds:
            path = Path(folder) / f'{name}.{seed}{src.suffix}'
            path.write_bytes(flipped(raw, seed, flips))
            paths.append(path)
        strict = strict_problems(storage, paths, mcap_python)
        out[name] = [(seed, outcome(p, ref), strict[str(p)]) for seed, p in zip(seeds, paths)]
        for p in paths:
            p.unlink()
    return out


def silent_where_damaged(rows):
    """Return the rows the rule forbids: silent while the strict reader reports damage."""
    return [r for r in rows if r[1] == 'silent' and r[2]]


def _main(argv):
    import argparse
    from pathlib import Path
    import tempfile
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: formats.*, conftest
    from conftest import SHARED_DATA
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('copies', type=int, nargs='?', default=20)
    parser.add_argument('--flips', type=int, default=20)
    parser.add_argument('--mcap-python', help='an interpreter that has the mcap package')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        result = sweep(SHARED_DATA / 'bags', folder, range(args.copies), args.flips,
                       args.mcap_python)
    print(f'| bag | copies ({args.flips} bit flips each) | same | warned | refused | silent, '
          'strict reader sees no damage | silent where the strict reader sees damage |')
    print('|---|---|---|---|---|---|---|')
    for name, rows in result.items():
        judged = all(r[2] is not None for r in rows)
        count = {k: sum(r[1] == k for r in rows) for k in ('same', 'warned', 'refused')}
        silent = [r for r in rows if r[1] == 'silent']
        bad = silent_where_damaged(rows) if judged else None
        print(f'| {name} | {len(rows)} | {count["same"]} | {count["warned"]} | '
              f'{count["refused"]} | {len(silent) - len(bad or [])} | '
              f'{"not judged (no mcap package)" if bad is None else len(bad)} |')
        for r in bad or []:
            print(f'  silent: seed {r[0]}: {r[2]}')


if __name__ == '__main__':
    if sys.argv[1:2] == ['--strict-mcap']:
        print(json.dumps(strict_mcap(sys.argv[2:])))
    else:
        _main(sys.argv[1:])
