"""What every command shares: one parser (no abbreviations), one error guard."""

from imu_allan.cli import analyze, discrepancy, gx3_sim
from imu_allan.cli.common import guarded
from imu_allan.errors import InputError
import pytest


@pytest.mark.parametrize('module, argv', [
    (analyze, ['data.csv', '--export-s', 'out.csv']),   # not --export-samples
    (analyze, ['data.csv', '--jso']),
    (discrepancy, ['data.csv', '--max', '3']),
    (gx3_sim, ['--rate', '200']),
])
def test_abbreviated_options_are_refused(module, argv, capsys):
    """A prefix of an option is an error (exit 2, one line), never silently expanded."""
    with pytest.raises(SystemExit) as exc:
        module.build_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'unrecognized arguments' in err[0]


def test_guard_turns_bad_input_into_one_line_and_status_2(capsys):
    """Bad input (InputError, OSError): one stderr line naming the input, exit status 2."""
    @guarded
    def bad(argv=None):
        raise InputError('data.csv', 'no samples')

    @guarded
    def missing(argv=None):
        open('/nonexistent/file.csv', encoding='utf-8')

    assert bad() == 2 and missing() == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].endswith('data.csv: no samples')
    assert '/nonexistent/file.csv' in lines[1] and len(lines) == 2
