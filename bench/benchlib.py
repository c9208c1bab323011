"""
Shared by the benchmarks: the machine line, best-of timing and goal lines.

Every figure is printed with the machine it was measured on (CPU model, cores, SIMD flags)
and the load average at the time, so that figures from different machines or conditions are
not compared by accident.
"""

import os
from pathlib import Path
import platform
import time

_SIMD = ('sse4_2', 'avx', 'avx2', 'fma', 'avx512f', 'avx512dq', 'avx512vl', 'neon', 'asimd')


def machine():
    """One line: CPU model, cores, SIMD flags, Python and numpy versions."""
    import numpy as np
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            key, _, value = line.partition(':')
            key = key.strip()
            if key == 'model name':
                model = value.strip()
            elif key in ('flags', 'Features'):
                flags = set(value.split())
    except OSError:
        pass
    simd = ' '.join(f for f in _SIMD if f in flags) or 'unknown'
    return (f'{model}, {os.cpu_count()} cores, SIMD {simd}, Python '
            f'{platform.python_version()}, numpy {np.__version__}')


def load():
    """Return the 1-minute load average (other processes sharing the cores), as text."""
    try:
        return f'load {os.getloadavg()[0]:.1f}'
    except OSError:
        return 'load ?'


def header(name):
    """Print the benchmark's first line: name, date and machine."""
    print(f'{name}: {time.strftime("%Y-%m-%d %H:%M %Z")} on {machine()}', flush=True)


def best_of(fn, repeat=5):
    """Run ``fn`` ``repeat`` times; return (result, best wall s, best CPU s of this process)."""
    best_wall = best_cpu = float('inf')
    out = None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best_wall = min(best_wall, time.perf_counter() - w0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return out, best_wall, best_cpu


def goal(text, met):
    """Print one goal with met / NOT met, the machine's load and its CPU; return ``met``."""
    cpu = machine().split(',')[0]
    print(f'GOAL {text}: {"met" if met else "NOT met"}  [{cpu}, {os.cpu_count()} cores, '
          f'{load()}]', flush=True)
    return bool(met)
