"""CSV samples, thesis logs and the read_samples dispatcher."""


from conftest import SHARED_DATA
from imu_allan.core.units import AXES
from imu_allan.errors import InputError
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.csv_samples import read_csv, write_csv
from imu_allan.formats.readers import detect_format, read_samples
from imu_allan.formats.samples import Samples
from imu_allan.formats.thesis_log import read_thesis_log
import numpy as np
import pytest

DATA = SHARED_DATA

# ------------------------------------------------------------------------------------ CSV


def test_csv_round_trip_is_exact(tmp_path):
    """write_csv -> read_csv gives the same float64 bits, extra columns included."""
    rng = np.random.default_rng(7)
    n = 1234
    data = rng.normal(size=(n, 6)) * np.array([1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2])
    data[0] = [np.pi, -0.0, 5e-324, 1.7976931348623157e308, 1 / 3, 2 / 3]  # awkward floats
    t = 1_700_000_000.0 + np.arange(n) / 400.0 + rng.uniform(0, 1e-6, n)
    mag = rng.normal(size=n) * 2e-5
    s = Samples(t=t, data=data, extra={'mag_x': mag})
    path = tmp_path / 's.csv'
    write_csv(path, s)
    assert path.read_text().splitlines()[0] == 't,' + ','.join(AXES) + ',mag_x'
    r = read_csv(path)
    assert r.axes == AXES
    assert np.array_equal(r.t, t) and np.array_equal(r.data, data)
    assert np.array_equal(r.extra['mag_x'], mag)
    assert np.signbit(r.data[0, 1])  # even -0.0 survives


def test_csv_subset_of_axes_any_order(tmp_path):
    """A subset of axis columns in any order reads back in AXES order; comments are skipped."""
    path = tmp_path / 'g.csv'
    path.write_text('# a comment\nt,gyro_z,gyro_x\n0.0,3,1\n\n0.01,6,4\n')
    r = read_csv(path)
    assert r.axes == ('gyro_x', 'gyro_z')
    assert r.data.tolist() == [[1.0, 3.0], [4.0, 6.0]]
    assert r.t.tolist() == [0.0, 0.01]


def test_csv_header_only_and_one_sample(tmp_path):
    """A header with no rows (n = 0) and a single row are read; the analyzer decides."""
    path = tmp_path / 'h.csv'
    path.write_text('t,accel_z\n')
    r = read_csv(path)
    assert r.n == 0 and r.axes == ('accel_z',) and r.data.shape == (0, 1)
    path.write_text('t,accel_z\n1.5,9.81\n')
    r = read_csv(path)
    assert r.n == 1 and r.data.tolist() == [[9.81]]


@pytest.mark.parametrize('text, message', [
    ('', 'empty file'),
    ('\n\n', 'empty file'),
    ('time,gyro_x\n0,1\n', 'no t column'),
    ('t,gyro_x,gyro_x\n0,1,1\n', 'appears twice'),
    ('t,gyro_q\n0,1\n', "unknown column 'gyro_q'"),
    ('t,mag_x,gyro_x\n0,1,1\n', "unknown column 'mag_x'"),  # extras only after the axes
    ('t,mag_x\n0,1\n', 'no axis column'),
    ('t,gyro_x\n0,1\n0.1,abc\n', "line 3, column gyro_x: not a number: 'abc'"),
    ('t,gyro_x,gyro_y\n0,1,2\n0.1,1\n', 'line 3: 2 cells, the header has 3'),
    ('t,gyro_x\n0,1\n0.1,2\n0.2,nan\n0.3,inf\n', 'line 4, column gyro_x: nan'),
    ('t,gyro_x\n0,1\n0.1,-inf\n', 'line 3, column gyro_x: -inf'),
    ('t,gyro_x\nnan,1\n', 'line 2, column t: nan'),
])
def test_csv_bad_input(tmp_path, text, message):
    """Every bad CSV is a one-line InputError naming the file, line and column."""
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(InputError) as err:
        read_csv(path)
    assert str(err.value).startswith(f'{path}: ')
    assert message in str(err.value)
    assert '\n' not in str(err.value)


def test_csv_missing_and_binary(tmp_path):
    """A missing file and a binary file are InputErrors."""
    with pytest.raises(InputError, match='no such file'):
        read_csv(tmp_path / 'none.csv')
    path = tmp_path / 'bin.csv'
    path.write_bytes(b'\xcb\xff\xfe\x00' * 10)
    with pytest.raises(InputError, match='not a text file'):
        read_csv(path)


# --------------------------------------------------------------------------------- thesis

THESIS_LOG = """\
Computed gyro bias (x;y;z): = 0.001043793745; 0.004222712480; -0.010834034532
    Data corresponds to accelerations(x;y;z); gyro rates(x;y;z); time stamp
    Time stamp are nanoseconds from 1st Jan 1970
    Acceleration vector needs to be scaled by gravity modulus at measure location: 9.80261
0.157141372561; -0.085792757571; -0.987031161785; 0.002211321611; 0.000542887487; \
0.000787906349; 1445776339557671000
0.157148823142; -0.085057221353; -0.985958039761; 0.002204418881; 0.002576438244; \
0.000352729112; 1445776339567671000
0.157509967685: -0.084938399494: -0.985969305038: -0.003598247189: -0.000587796094: \
0.002855019644: 1445776339577671000
0.156996262940; -0.085416853428; -0.985828942039; \\ 0.096181766745; -0.095259370130; \
-0.091097677056; \\ 1445776339597671000; -0.091097677056; -0.091097677056
0.156540662050; -0.086023531854; -0.986292302608; -0.001110073412; -0.001267342130; \
0.007276295684; 1445776339607671000
\\{0.156555846334; -0.084085874259; -0.985709607601; 0.002503974363; 0.001690430101; \
0.001233174466; 1445776339637671000\\}
0.156912237406; -0.084688827395; -0.985474646091; 0.004660217091; 0.008004894480; \
0.002879807726; 1445776339647671000
"""


def test_thesis_log_parsing(tmp_path):
    """The thesis figure 4.2 sample: gravity from the header, g -> m/s^2, damaged lines skipped."""
    path = tmp_path / 'imu_log.txt'
    path.write_text(THESIS_LOG)
    s = read_thesis_log(path)
    assert s.gravity == 9.80261
    assert s.axes == AXES
    assert s.n == 5  # 4 good ';' lines + 1 ':' line; the backslash and brace lines skipped
    assert s.data[0].tolist() == [0.002211321611, 0.000542887487, 0.000787906349,
                                  0.157141372561 * 9.80261, -0.085792757571 * 9.80261,
                                  -0.987031161785 * 9.80261]
    assert s.t[0] == 1445776339 + 0.557671
    assert np.allclose(np.diff(s.t), [0.01, 0.01, 0.03, 0.04], atol=1e-6)
    assert any('2 malformed line(s) skipped (line 8, 10)' in w for w in s.warnings)
    assert any("1 line(s) with ':'" in w for w in s.warnings)
    assert detect_format(path) == 'thesis'
    assert read_samples(path).data.tolist() == s.data.tolist()


def test_thesis_log_default_gravity_and_errors(tmp_path):
    """No gravity in the header means 9.80665; a file with no data line is an InputError."""
    path = tmp_path / 'plain.txt'
    path.write_text('0.0; 0.0; 1.0; 0.1; 0.2; 0.3; 1000000000\n'
                    '0.0; 0.0; 1.0; 0.1; 0.2; 0.3; 1010000000\n')
    s = read_thesis_log(path)
    assert s.gravity == 9.80665 and s.data[0, 5] == 9.80665 and s.warnings == []
    assert s.t.tolist() == [1.0, 1.01]
    path.write_text('header only\nnothing else\n')
    with pytest.raises(InputError, match='no data line'):
        read_thesis_log(path)
    with pytest.raises(InputError, match='no such file'):
        read_thesis_log(tmp_path / 'missing.txt')


# ------------------------------------------------------------------------------- dispatch


def test_detect_and_read_every_format(tmp_path):
    """Auto-detection by folder, extension and content; explicit formats are checked."""
    s = Samples(t=np.arange(50) / 100.0 + 10.0, data=np.random.default_rng(1).normal(size=(50, 6)))
    csv = tmp_path / 'a.csv'
    write_csv(csv, s)
    nosuffix = tmp_path / 'samples_export'
    write_csv(nosuffix, s)
    mcap = tmp_path / 'm'
    write_imu_bag(mcap, s, storage='mcap')
    sq = tmp_path / 'q'
    write_imu_bag(sq, s, storage='sqlite3')
    ros1 = tmp_path / 'r.bag'
    write_imu_bag(ros1, s, storage='ros1')
    bare = tmp_path / 'bare_copy'
    bare.write_bytes((mcap / 'm.mcap').read_bytes())  # MCAP without its extension
    cases = {csv: 'csv', nosuffix: 'csv', mcap: 'rosbag2', sq: 'rosbag2', ros1: 'ros1',
             mcap / 'm.mcap': 'rosbag2', sq / 'q.db3': 'rosbag2', bare: 'rosbag2'}
    for path, fmt in cases.items():
        assert detect_format(path) == fmt, path
        r = read_samples(path)
        assert np.array_equal(r.data, s.data), path
        assert np.max(np.abs(r.t - s.t)) < 1e-9
        assert np.array_equal(read_samples(path, fmt=fmt).data, s.data)
    with pytest.raises(InputError, match='not a ROS 1 bag'):
        read_samples(mcap, fmt='ros1')
    with pytest.raises(InputError, match='use --format ros1'):
        read_samples(ros1, fmt='rosbag2')
    with pytest.raises(InputError, match='unknown format'):
        read_samples(csv, fmt='xlsx')
    junk = tmp_path / 'junk.dat'
    junk.write_bytes(bytes(range(256)))
    with pytest.raises(InputError, match='unknown input format'):
        read_samples(junk)
    with pytest.raises(InputError, match='no such file'):
        read_samples(tmp_path / 'missing.csv')
    with pytest.raises(InputError, match='no such file'):
        read_samples(tmp_path / 'missing', fmt='csv')


@pytest.mark.skipif(not (DATA / 'gx3_25_captures').is_dir(), reason='GX3 captures not found')
def test_gx3raw_detected_and_dispatched():
    """A raw 3DM-GX3-25 capture is recognised by its first byte and read by the GX3 reader."""
    path = DATA / 'gx3_25_captures' / '20140313_191853.3dmgx3.log'
    assert detect_format(path) == 'gx3raw'
    s = read_samples(path)
    assert s.n > 50 and s.data.shape[1] == len(s.axes)


def test_thesis_log_fast_and_line_paths_agree(tmp_path):
    """
    Long logs are parsed in numpy blocks; a damaged block falls back to line parsing.

    Both must give Python's float() of every field and the exact integer stamps.
    """
    rng = np.random.default_rng(5)
    n = 45_000
    vals = rng.normal(0.0, 0.01, size=(n, 6))
    ns = 1445776339557671000 + np.arange(n, dtype=np.int64) * 10_000_000
    lines = ['; '.join(f'{v:.12f}' for v in vals[i]) + f'; {ns[i]}' for i in range(n)]
    lines[30_123] = '\\\\{' + lines[30_123] + '\\\\}'  # damaged line in the second block
    path = tmp_path / 'long.txt'
    path.write_text('gravity modulus at measure location: 9.8\n' + '\n'.join(lines) + '\n')
    s = read_thesis_log(path)
    keep = np.ones(n, dtype=bool)
    keep[30_123] = False
    expect = np.array([[float(x) for x in ln.split(';')[:6]] for ln in
                       np.array(lines, dtype=object)[keep]])
    assert s.n == n - 1
    assert np.array_equal(s.data[:, :3], expect[:, 3:])
    assert np.array_equal(s.data[:, 3:], expect[:, :3] * 9.8)
    sec = ns[keep] // 1_000_000_000
    assert np.array_equal(s.t, sec + (ns[keep] - sec * 1_000_000_000) * 1e-9)
    assert s.warnings == ['1 malformed line(s) skipped (line 30125)']
