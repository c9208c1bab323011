"""
``analyze`` on many inputs: scan folders, run one Dask task per input, record in DuckDB.

Each input's whole analysis (read, estimate, fit, report files) is one task,
:func:`analyze_task`, the same function the single-input path runs, so the numbers do not
depend on where it ran.  Tasks go to a local Dask cluster of worker processes sized to the
machine, or to an existing ``dask.distributed`` scheduler (``--scheduler tcp://HOST:PORT``; the
workers must see the input paths, for example on shared storage).  Results come back to this
process, which prints them and writes each to the ``--db`` history as it arrives, one
transaction per input.

A worker that dies takes its task with it; the scheduler gives the task to another worker, and
after :data:`ALLOWED_FAILURES` + 1 deaths with the same task (a bag that kills whatever reads
it) gives up on it: that input becomes an error row, the others go on.  Every input is answered
exactly once (one future per input, read once).
"""

from collections import Counter
import contextlib
import logging
import os
from pathlib import Path
import sys

from .common import emit, EXIT_BAD_INPUT
from .progress import RunProgress
from ..errors import InputError
from ..report import strict_json

#: Worker deaths a task may be part of before it is given up (Dask's scheduler setting
#: ``distributed.scheduler.allowed-failures``; its default is 3).  A bag that crashes the
#: process reading it should not take down three workers; one unlucky death should not fail it.
ALLOWED_FAILURES = 2
CONNECT_TIMEOUT_S = 20
DASK_HINT = "needs dask.distributed: pip install 'dask[distributed]'"
BAG_SUFFIXES = {'.mcap': '.mcap', '.db3': '.db3', '.bag': 'ROS 1 .bag'}


def is_scan_folder(path):
    """Return True for a folder to scan (a folder that is not itself a rosbag2 bag)."""
    p = Path(path)
    return p.is_dir() and not (p / 'metadata.yaml').exists()


def _walk(root):
    """Yield ``(kind, path)`` of the bags under ``root`` (sorted, hidden folders skipped)."""
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith('.'))
        if 'metadata.yaml' in files:
            dirs[:] = []  # a rosbag2 folder is one input; its .mcap/.db3 are not scanned
            yield 'rosbag2 folder', folder
            continue
        for name in sorted(files):
            kind = BAG_SUFFIXES.get(Path(name).suffix.lower())
            if kind:
                yield kind, os.path.join(folder, name)


def scan_inputs(paths):
    """
    Expand folders into the bags they hold; return ``(inputs, counts by kind)``.

    Folders are scanned recursively for rosbag2 folders (with a ``metadata.yaml``), ``.mcap`` and
    ``.db3`` files outside them and ROS 1 ``.bag`` files; CSV files and logs count only when
    named.  Duplicates (the same absolute path) are dropped.
    """
    found, counts, seen = [], Counter(), set()
    for path in paths:
        if is_scan_folder(path):
            items = list(_walk(path))
            if not items:
                raise InputError(path, 'no bags in this folder (rosbag2 folders, .mcap, .db3, '
                                       '.bag; name CSV and log files explicitly)')
        elif Path(path).is_dir():
            items = [('rosbag2 folder', path)]
        else:
            items = [(BAG_SUFFIXES.get(Path(path).suffix.lower(), 'other file'), path)]
        for kind, item in items:
            key = os.path.abspath(item)
            if key not in seen:
                seen.add(key)
                found.append(str(item))
                counts[kind] += 1
    return found, counts


def analyze_task(path, args, options, out_dir=None):
    """
    Analyse one input, wherever it runs; never raises for a bad input.

    Returns a dict: ``input``, ``ok`` and either ``report`` (the JSON report) and ``text`` (the
    console summary) or ``error`` (one line naming the input).
    """
    from .one_input import run_one
    try:
        report, text = run_one(path, args, options, out_dir=out_dir)
    except InputError as exc:
        return {'input': path, 'ok': False, 'error': str(exc)}
    except Exception as exc:  # an unforeseen failure stays with its input; the others go on
        return {'input': path, 'ok': False, 'error': f'{path}: {_one_line(exc)}'}
    return {'input': path, 'ok': True, 'report': report, 'text': text}


def _one_line(exc):
    text = ' '.join(str(exc).split())
    text = f'{type(exc).__name__}: {text}' if text else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + '...'


def _out_dirs(inputs, out):
    """One sub-folder of ``--out`` per input, named after it (made unique)."""
    if not out:
        return dict.fromkeys(inputs)
    dirs, used = {}, Counter()
    for p in inputs:
        name = Path(str(p).rstrip('/')).name.replace('.', '_')
        used[name] += 1
        dirs[p] = str(Path(out) / (name if used[name] == 1 else f'{name}_{used[name]}'))
    return dirs


class History:
    """The ``--db`` side of a run: what to skip, and one transaction per finished input."""

    def __init__(self, path, imu_id=None):
        """Read what is known; the file is then opened only while writing (:meth:`session`)."""
        from ..history import db
        self.db, self.path, self.imu_id = db, path, imu_id
        self.known = db.known_inputs(path)
        self.con = None

    @contextlib.contextmanager
    def session(self):
        """Keep the database open for the :meth:`record` calls inside (one per input)."""
        with self.db.connect(self.path) as con:
            self.con = con
            try:
                yield self
            finally:
                self.con = None

    def fingerprint(self, path):
        """``(size, mtime)`` of an input, None if it cannot be read (the analysis will say)."""
        try:
            return self.db.fingerprint(path)
        except OSError:
            return None

    def is_known(self, path, fingerprint):
        """Return True if the input was recorded with this same size and mtime."""
        return fingerprint is not None and \
            self.known.get(self.db.abspath(path)) == fingerprint

    def record(self, outcome, fingerprint):
        """Write one outcome (its inputs row and measurements) in one transaction."""
        from .. import __version__
        from ..history.rows import measurement_rows
        now = self.db.utc_now()
        key = self.db.abspath(outcome['input'])
        size, mtime = fingerprint or (None, None)
        entry = {'input': key, 'size': size, 'mtime': mtime,
                 'status': 'ok' if outcome['ok'] else 'error',
                 'error': outcome.get('error'), 'analyzed_at': now, 'version': __version__}
        rows = measurement_rows(outcome['report'], key, now, self.imu_id) if outcome['ok'] \
            else []
        with self.session() if self.con is None else contextlib.nullcontext():
            self.db.record(self.con, entry, rows)


def _dask_client(args, n_inputs):
    """Return a client of the given scheduler, or of a new local cluster; ``(client, cluster)``."""
    where = '--scheduler' if args.scheduler else 'analyze'
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError:  # optional (package.xml says so): one line saying what to install
        raise InputError(where, DASK_HINT) from None
    logging.getLogger('distributed').setLevel(logging.ERROR)
    if args.scheduler:
        try:
            return Client(args.scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False), None
        except (OSError, TimeoutError) as err:
            raise InputError(args.scheduler, f'cannot reach the Dask scheduler: '
                                             f'{_one_line(err)}') from None
    n = min(args.workers or os.cpu_count() or 1, n_inputs)
    with dask.config.set({'distributed.scheduler.allowed-failures': ALLOWED_FAILURES}):
        # one single-threaded process per core; numba too, or two kernels would share a core
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR,
                               env={'NUMBA_NUM_THREADS': '1'})
    return Client(cluster, set_as_default=False), cluster


def _run_dask(work, args, options, out_dirs, done):
    """Submit one task per input; call ``done(outcomes)`` with each batch that finished."""
    from argparse import Namespace
    client, cluster = _dask_client(args, len(work))  # first: says what to install
    try:
        from distributed import as_completed, KilledWorker
    except ImportError:  # cannot happen after _dask_client; keeps the import visibly optional
        raise InputError('analyze', DASK_HINT) from None
    # each task gets the options, not the list of every input
    task_args = Namespace(**dict(vars(args), inputs=[]))
    try:
        futures = {client.submit(analyze_task, path, task_args, options, out_dirs[path],
                                 pure=False): path for path in work}
        for batch in as_completed(futures, loop=client.loop).batches():
            outcomes = []
            for future in batch:
                path = futures[future]
                try:
                    outcomes.append(future.result())
                except KilledWorker:
                    outcomes.append({'input': path, 'ok': False,
                                     'error': f'{path}: the worker analysing it died '
                                              f'{ALLOWED_FAILURES + 1} times'})
                except Exception as exc:  # the task could not run (pickling, lost scheduler)
                    outcomes.append({'input': path, 'ok': False,
                                     'error': f'{path}: {_one_line(exc)}'})
                future.release()
            done(outcomes)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _summary_table(rows):
    from ..core.units import conventional
    head = (f'{"input":40} {"samples":>9} {"rate Hz":>8} {"hours":>6} {"static":>6} '
            f'{"gyro N worst (deg/sqrt(h))":>27} {"accel N worst (m/s/sqrt(h))":>28}')
    lines = ['summary:', head]
    for name, rep in rows:
        if isinstance(rep, str):
            lines.append(f'{name[-40:]:40} error: {rep}')
            continue
        kal = rep['kalibr']
        g = kal.get('gyroscope_noise_density')
        a = kal.get('accelerometer_noise_density')
        g_txt = f'{conventional("gyro_x", "white_noise", g)[0]:.4g}' if g else '-'
        a_txt = f'{conventional("accel_x", "white_noise", a)[0]:.4g}' if a else '-'
        lines.append(f'{name[-40:]:40} {rep["n_samples"]:>9} {rep["sample_rate_hz"]:>8.4g} '
                     f'{rep["duration_s"] / 3600:>6.2f} {str(rep["verdict"]["static"]):>6} '
                     f'{g_txt:>27} {a_txt:>28}')
    return '\n'.join(lines)


def _scan_line(inputs, counts):
    kinds = ', '.join(f'{n} {k}{"s" if n > 1 and k.endswith("folder") else ""}'
                      for k, n in counts.items())
    return f'analyze: {len(inputs)} input(s): {kinds}'


def run_batch(args, options):
    """Analyse every input of ``args`` (folders scanned); return the exit status."""
    if args.scheduler and not _have_dask():
        raise InputError('--scheduler', DASK_HINT)
    history = History(args.db, args.imu_id) if args.db else None  # or: what to install
    inputs, counts = scan_inputs(args.inputs)
    if args.export_samples and len(inputs) > 1:
        raise InputError('--export-samples', 'takes exactly one INPUT')
    quiet = args.quiet
    say = (lambda line: None) if quiet else (lambda line: print(line, file=sys.stderr))
    say(_scan_line(inputs, counts))
    prints = {p: history.fingerprint(p) for p in inputs} if history else {}
    work = [p for p in inputs if args.force or not history or
            not history.is_known(p, prints[p])]
    skipped = [p for p in inputs if p not in set(work)]
    if skipped:
        say(f'analyze: {len(skipped)} input(s) already in {args.db} with the same size and '
            f'mtime, skipped (--force analyses them again)')
    out_dirs = _out_dirs(work, args.out)
    progress = RunProgress(len(work), tty=sys.stderr.isatty(), enabled=not quiet)
    outcomes = {}

    def done(batch):
        with history.session() if history else contextlib.nullcontext():
            for outcome in batch:
                if history:
                    history.record(outcome, prints[outcome['input']])
                outcomes[outcome['input']] = outcome
                progress.finished(outcome['input'], outcome.get('error'))

    try:
        if args.scheduler or len(work) > 1 and _have_dask():
            _run_dask(work, args, options, out_dirs, done)
        else:
            if len(work) > 1:
                say(f'analyze: dask is not installed, analysing {len(work)} inputs one after '
                    f"another (pip install 'dask[distributed]' to use every core)")
            for path in work:
                done([analyze_task(path, args, options, out_dirs[path])])
    finally:
        progress.close()
    results = [outcomes[p] for p in work]
    failed = [o for o in results if not o['ok']]
    if args.out and results:  # one page per input is in its sub-folder; the index links them
        from ..report.html import write_batch_index
        try:
            write_batch_index(args.out, results, out_dirs)
        except OSError as exc:
            raise InputError(args.out, f'cannot write index.html ({exc.strerror or exc})') \
                from None
    for o in failed:
        sys.stderr.write(f'analyze: {o["error"]}\n')
    if args.json:
        emit(strict_json.dumps({'reports': [o['report'] for o in results if o['ok']],
                                'errors': [o['error'] for o in failed], 'skipped': skipped}))
    else:
        for o in results:
            if o['ok']:
                print(o['text'] + '\n')
        print(_summary_table([(o['input'], o['report'] if o['ok'] else o['error'])
                              for o in results]))
        print(f'{len(results) - len(failed)} analysed, {len(failed)} failed'
              + (': ' + ', '.join(o['input'] for o in failed) if failed else '')
              + (f', {len(skipped)} skipped (already in {args.db})' if skipped else ''))
    return EXIT_BAD_INPUT if failed else 0


def _have_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True
