"""Run every benchmark in bench/ (``make bench``) and print the results with the machine."""

from pathlib import Path
import platform
import subprocess
import sys
import time


def main():
    """Run bench/bench_*.py one after the other; exit non-zero if any fails."""
    root = Path(__file__).resolve().parents[1]
    print(f'machine: {platform.node()} {platform.machine()}, {_cpu()}, Python '
          f'{platform.python_version()}, {time.strftime("%Y-%m-%d")}')
    failed = 0
    for script in sorted((root / 'bench').glob('bench_*.py')):
        print(f'--- {script.name}', flush=True)
        proc = subprocess.run([sys.executable, str(script)], cwd=root)
        failed += proc.returncode != 0
    return 1 if failed else 0


def _cpu():
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cores = len([x for x in Path('/proc/cpuinfo').read_text().splitlines()
                             if x.startswith('processor')])
                return f'{line.split(":", 1)[1].strip()} x {cores}'
    except OSError:
        pass
    return platform.processor() or 'unknown CPU'


if __name__ == '__main__':
    raise SystemExit(main())
