"""
Run every benchmark in bench/ (``make bench``) and print the results with the machine.

Each script prints its figures and ``GOAL ...: met / NOT met [CPU, cores, load]`` lines
(``bench/benchlib.py``); they are repeated at the end under the machine line (CPU model, cores,
SIMD flags), so that figures from different machines are not compared by accident.
"""

from pathlib import Path
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'bench'))

from benchlib import load, machine  # noqa: E402


def main():
    """Run bench/bench_*.py one after the other; exit non-zero if any fails."""
    stamp = f'{time.strftime("%Y-%m-%d %H:%M %Z")}, {machine()}'
    print(f'machine: {stamp}', flush=True)
    failed, goals = 0, []
    for script in sorted((ROOT / 'bench').glob('bench_*.py')):
        print(f'--- {script.name} ({load()})', flush=True)
        proc = subprocess.Popen([sys.executable, str(script)], cwd=ROOT,
                                stdout=subprocess.PIPE, text=True)
        for line in proc.stdout:
            print(line, end='', flush=True)
            if line.startswith('GOAL '):
                goals.append(line.rstrip())
        failed += proc.wait() != 0
    print(f'--- goals, measured {stamp}')
    print('\n'.join(goals) if goals else '(none)')
    return 1 if failed else 0


if __name__ == '__main__':
    raise SystemExit(main())
