"""Bag reading and writing: real bags, topics, damaged input, fast == generic, round trips."""

import os
import shutil

from conftest import SHARED_DATA
from imu_allan.errors import InputError
from imu_allan.formats.bag_reader import bag_topics, list_imu_topics, read_bag
from imu_allan.formats.bag_writer import copy_bag_with_topic, write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

DATA = SHARED_DATA / 'bags'
needs_data = pytest.mark.skipif(not DATA.is_dir(),
                                reason=f'real test bags not found in {DATA}')
JAZZY = get_typestore(Stores.ROS2_JAZZY)
JACKAL = ('test2.bag', 'jackal_test2_sqlite3', 'jackal_test2_mcap',
          'jackal_test2_mcap/jackal_test2_mcap.mcap',
          'jackal_test2_sqlite3/jackal_test2_sqlite3.db3')


def _samples(n=500, rate=100.0, seed=3, t0=1_700_000_000.0):
    rng = np.random.default_rng(seed)
    data = rng.normal(0.0, 0.01, size=(n, 6))
    data[:, 5] += 9.81
    return Samples(t=t0 + np.arange(n) / rate, data=data)


def _same(a, b):
    return np.array_equal(a.t, b.t) and np.array_equal(a.data, b.data)


# ---------------------------------------------------------------------------------------- real


@needs_data
def test_jackal_bag_same_in_all_three_forms():
    """ROS 1, sqlite3 and MCAP forms of test2: 3,061 messages, identical values, both paths."""
    ref = read_bag(DATA / 'test2.bag', fast=False)
    assert ref.n == 3061
    assert ref.t[0] == pytest.approx(47.58)
    assert ref.t[-1] - ref.t[0] == pytest.approx(61.2, abs=0.05)
    # A moving robot: gravity mostly on z, and the rates vary.
    assert 9.0 < np.median(ref.data[:, 5]) < 10.5
    assert np.std(ref.data[:, 2]) > 0.01
    for name in JACKAL:
        for fast in (True, False):
            s = read_bag(DATA / name, fast=fast)
            assert s.n == 3061, (name, fast)
            assert _same(s, ref), (name, fast)
            assert s.warnings == []
            assert s.source.endswith(':/imu/data')


@needs_data
def test_husky_bag_and_topic_listing():
    """Topic listing with counts: Husky bag (11,865 Imu on /imu/data) and the Jackal forms."""
    topics = bag_topics(DATA / 'test1.bag')
    assert topics['/imu/data'] == ('sensor_msgs/msg/Imu', 11865)
    assert topics['/fix'][0] == 'sensor_msgs/msg/NavSatFix'
    assert list_imu_topics(DATA / 'test1.bag') == ['/imu/data']
    fast = read_bag(DATA / 'test1.bag')
    assert fast.n == 11865
    assert _same(fast, read_bag(DATA / 'test1.bag', topic='/imu/data', fast=False))
    for name in ('jackal_test2_mcap', 'jackal_test2_sqlite3', 'test2.bag'):
        assert list_imu_topics(DATA / name) == ['/imu/data']
        assert bag_topics(DATA / name)['/jackal_velocity_controller/odom'][1] == 3060


@needs_data
def test_named_topic_of_other_type_and_unknown_topic():
    """A named topic of another type, or an unknown one, is an InputError naming it."""
    for name in ('test2.bag', 'jackal_test2_mcap', 'jackal_test2_sqlite3'):
        for fast in (True, False):
            with pytest.raises(InputError, match='nav_msgs/msg/Odometry, not sensor_msgs'):
                read_bag(DATA / name, topic='/jackal_velocity_controller/odom', fast=fast)
            with pytest.raises(InputError, match=r'no topic /nope \(Imu topics: /imu/data\)'):
                read_bag(DATA / name, topic='/nope', fast=fast)


# ------------------------------------------------------------------------------ topic choice


def _odom(stamp_ns):
    ts = JAZZY.types
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return ts['nav_msgs/msg/Odometry'](
        header=ts['std_msgs/msg/Header'](
            stamp=ts['builtin_interfaces/msg/Time'](sec=sec, nanosec=nsec), frame_id='odom'),
        child_frame_id='base_link',
        pose=ts['geometry_msgs/msg/PoseWithCovariance'](
            pose=ts['geometry_msgs/msg/Pose'](
                position=ts['geometry_msgs/msg/Point'](x=1.0, y=2.0, z=0.0),
                orientation=ts['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.zeros(36)),
        twist=ts['geometry_msgs/msg/TwistWithCovariance'](
            twist=ts['geometry_msgs/msg/Twist'](
                linear=ts['geometry_msgs/msg/Vector3'](x=0.5, y=0.0, z=0.0),
                angular=ts['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.1)),
            covariance=np.zeros(36)))


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_several_imu_topics_need_a_choice(tmp_path, storage):
    """Two Imu topics: no silent pick; --topic chooses; an empty or non-Imu topic is an error."""
    s = _samples(200)
    second = _samples(50, seed=9)
    from imu_allan.formats.imu_cdr import encode_imu
    rows, stamps = encode_imu(second.t, second.data, 'imu2')
    msgs = [(int(ns), JAZZY.deserialize_cdr(r.tobytes(), 'sensor_msgs/msg/Imu'))
            for ns, r in zip(stamps, rows)]
    odom = [(int(ns), _odom(int(ns))) for ns in stamps[:20]]
    path = tmp_path / 'two'
    write_imu_bag(path, s, topic='/imu/a', storage=storage,
                  extra_topics={'/imu/b': ('sensor_msgs/msg/Imu', msgs),
                                '/odom': ('nav_msgs/msg/Odometry', odom),
                                '/imu/empty': ('sensor_msgs/msg/Imu', [])})
    assert sorted(list_imu_topics(path)) == ['/imu/a', '/imu/b', '/imu/empty']
    for fast in (True, False):
        with pytest.raises(InputError) as err:
            read_bag(path, fast=fast)
        assert 'several Imu topics' in str(err.value) and '--topic' in str(err.value)
        assert '/imu/a' in str(err.value) and '/imu/b' in str(err.value)
        a = read_bag(path, topic='/imu/a', fast=fast)
        b = read_bag(path, topic='/imu/b', fast=fast)
        assert a.n == 200 and b.n == 50
        assert np.array_equal(a.data, s.data) and np.array_equal(b.data, second.data)
        with pytest.raises(InputError, match='topic /imu/empty has no messages'):
            read_bag(path, topic='/imu/empty', fast=fast)
        with pytest.raises(InputError, match='is nav_msgs/msg/Odometry'):
            read_bag(path, topic='/odom', fast=fast)


def test_bag_without_imu_topic(tmp_path):
    """A bag with no Imu topic at all is an InputError."""
    path = tmp_path / 'odom_only'
    from rosbags.rosbag2 import StoragePlugin, Writer
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection('/odom', 'nav_msgs/msg/Odometry', typestore=JAZZY)
        w.write(c, 1000, JAZZY.serialize_cdr(_odom(1000), 'nav_msgs/msg/Odometry'))
    for fast in (True, False):
        with pytest.raises(InputError, match='no sensor_msgs/msg/Imu topic'):
            read_bag(path, fast=fast)


# ------------------------------------------------------------------------ fast == generic


def mixed_frame_bag(tmp_path, storage):
    """
    Write a bag whose topic /imu/mixed has 140 messages of 7 frame_id lengths interleaved.

    Lengths 1..12 hit every CDR padding case; the 300 base samples go on /imu/base.
    """
    s = _samples(300)
    ts = get_typestore(Stores.ROS1_NOETIC if storage == 'ros1' else Stores.ROS2_JAZZY)
    extra = []
    from imu_allan.formats.imu_cdr import encode_imu
    # Odd stamps with other frame ids.
    for i, fid in enumerate(['a', 'ab', 'abc', 'abcd', 'abcde', 'abcdef', 'abcdefghijkl']):
        t = s.t[:1] + 0.001 * (i + 1) + np.arange(20) * 0.01
        rows, stamps = encode_imu(t, s.data[:20] * (i + 2), fid, ros1=storage == 'ros1')
        for ns, r in zip(stamps, rows):
            msg = (ts.deserialize_ros1 if storage == 'ros1' else ts.deserialize_cdr)(
                r.tobytes(), 'sensor_msgs/msg/Imu')
            extra.append((int(ns), msg))
    path = tmp_path / ('mixed.bag' if storage == 'ros1' else 'mixed')
    write_imu_bag(path, s, topic='/imu/base', storage=storage,
                  extra_topics={'/imu/mixed': ('sensor_msgs/msg/Imu', extra)})
    return path


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
def test_mixed_frame_id_lengths_fast_equals_generic(tmp_path, storage):
    """Differing frame_id lengths (so differing CDR paddings) interleaved, plus other topics."""
    path = mixed_frame_bag(tmp_path, storage)
    fast = read_bag(path, topic='/imu/mixed', fast=True)
    gen = read_bag(path, topic='/imu/mixed', fast=False)
    assert fast.n == gen.n == 140
    assert _same(fast, gen)
    # the earliest message's frame id, from the bulk decoder's bytes as from the deserializer
    assert fast.frame_id == gen.frame_id == 'a'
    assert np.all(np.diff(fast.t) >= 0)  # receive-time order = stamp order here


def bad_nanosecond_bag(tmp_path, storage):
    """
    Write a bag whose topic /imu/n has 120 messages, 3 of them with nanosec >= 1e9.

    Returns (path, samples written, indices of the damaged messages); seeded positions.
    """
    from imu_allan.formats.imu_cdr import encode_imu
    s = _samples(120)
    ros1 = storage == 'ros1'
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_JAZZY)
    rows, stamps = encode_imu(s.t, s.data, 'imu_link', ros1=ros1)
    bad = np.random.default_rng(11).choice(120, 3, replace=False)
    msgs = []
    for i, (ns, r) in enumerate(zip(stamps, rows)):
        deserialize = ts.deserialize_ros1 if ros1 else ts.deserialize_cdr
        msg = deserialize(r.tobytes(), 'sensor_msgs/msg/Imu')
        if i in bad:
            msg.header.stamp.nanosec = 1_000_000_000 + 7 * i
        msgs.append((int(ns), msg))
    path = tmp_path / ('n.bag' if ros1 else 'n')
    write_imu_bag(path, _samples(10), topic='/imu/other', storage=storage,
                  extra_topics={'/imu/n': ('sensor_msgs/msg/Imu', msgs)})
    return path, s, bad


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
def test_impossible_nanoseconds_dropped_and_counted(tmp_path, storage):
    """
    A stamp whose nanosecond field is 1e9 or more is damage: dropped, counted, named.

    Three of 120 messages at seeded positions; the fast and the generic path drop the same
    ones and keep every other sample unchanged.
    """
    path, s, bad = bad_nanosecond_bag(tmp_path, storage)
    keep = np.setdiff1d(np.arange(120), bad)
    for fast in (True, False):
        r = read_bag(path, topic='/imu/n', fast=fast)
        assert r.n == 117, fast
        assert np.array_equal(r.data, s.data[keep]), fast
        assert any('3 damaged message(s)' in w and 'nanosecond' in w for w in r.warnings), \
            (fast, r.warnings)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
def test_write_read_round_trip(tmp_path, storage):
    """Samples -> bag -> samples: values bit-identical, stamps to the nanosecond."""
    s = _samples(2000, rate=400.0, t0=1_700_000_123.0)
    path = tmp_path / ('r.bag' if storage == 'ros1' else 'r')
    write_imu_bag(path, s, storage=storage, frame_id='gx3_25')
    assert list_imu_topics(path) == ['/imu/data_raw']
    for fast in (True, False):
        r = read_bag(path, fast=fast)
        assert r.n == 2000
        assert r.frame_id == 'gx3_25'
        assert np.array_equal(r.data, s.data)
        assert np.max(np.abs(r.t - s.t)) < 1e-6  # ns stamps; float64 at 1.7e9 s is 2.4e-7
    with pytest.raises(InputError, match='already exists'):
        write_imu_bag(path, s, storage=storage)


def test_compressed_mcap_and_partial_axes(tmp_path):
    """The writer refuses to overwrite; values come back bit-identical from every storage."""
    s = _samples(5000)
    gyro_only = Samples(t=s.t, data=s.data[:, :3], axes=('gyro_x', 'gyro_y', 'gyro_z'))
    path = tmp_path / 'z'
    write_imu_bag(path, gyro_only, storage='mcap', compress=True)
    fast = read_bag(path)
    assert _same(fast, read_bag(path, fast=False))
    assert np.array_equal(fast.data[:, :3], s.data[:, :3])
    assert not fast.data[:, 3:].any()  # absent axes are written as 0


# ----------------------------------------------------------------------------------- damage


def test_missing_and_not_a_bag(tmp_path):
    """MCAP with zstd chunks reads back; a gyro-only recording writes zero accelerations."""
    with pytest.raises(InputError, match='no such file or directory'):
        read_bag(tmp_path / 'nothing.mcap')
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(os.urandom(4000))
    with pytest.raises(InputError, match='not a bag'):
        read_bag(garbage)
    text = tmp_path / 'notes.bag'
    text.write_text('hello\n')
    with pytest.raises(InputError, match='not a bag'):
        read_bag(text)
    empty = tmp_path / 'empty.db3'
    empty.write_bytes(b'')
    with pytest.raises(InputError, match='empty file'):
        read_bag(empty)
    folder = tmp_path / 'folder'
    folder.mkdir()
    with pytest.raises(InputError, match='no metadata.yaml'):
        read_bag(folder)


def test_truncated_mcap_returns_readable_part_with_warning(tmp_path):
    """Missing path, random bytes, a text file named .bag, an empty file, a bare folder."""
    s = _samples(20000, rate=200.0)
    path = tmp_path / 'full'
    write_imu_bag(path, s, storage='mcap')
    raw = (path / 'full.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(raw[:len(raw) * 6 // 10])
    for fast in (True, False):
        r = read_bag(cut, fast=fast)
        assert 0 < r.n < 20000
        assert r.n > 20000 * 0.5  # everything before the cut, including the cut chunk's start
        assert np.array_equal(r.data, s.data[:r.n]) and np.array_equal(r.t, read_bag(
            path).t[:r.n])
        assert len(r.warnings) == 1 and 'truncated' in r.warnings[0]
    tiny = tmp_path / 'tiny.mcap'
    tiny.write_bytes(raw[:60])
    with pytest.raises(InputError, match='damaged MCAP, no Imu data readable'):
        read_bag(tiny)


def test_corrupt_compressed_chunk_is_skipped(tmp_path):
    """A cut MCAP gives its complete messages (the same values) and one warning."""
    s = _samples(30000, rate=200.0)
    path = tmp_path / 'z'
    write_imu_bag(path, s, storage='mcap', compress=True)
    f = path / 'z.mcap'
    raw = bytearray(f.read_bytes())
    # Break the zstd frame magic of the second chunk (rosbags writes no chunk CRC, so damage
    # inside the compressed payload could pass unnoticed; a broken frame cannot).
    magic = b'\x28\xb5\x2f\xfd'
    second = raw.index(magic, raw.index(magic) + 1)
    raw[second:second + 4] = b'\x00\x00\x00\x00'
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(bytes(raw))
    r = read_bag(bad)
    assert 0 < r.n < 30000
    assert any('corrupt chunk' in w for w in r.warnings)
    # The rows read are the original ones (a whole chunk is missing, nothing is garbled).
    idx = np.searchsorted(s.t, r.t)
    assert np.array_equal(s.data[idx], r.data)
    assert r.t[-1] == s.t[-1]  # the chunks after the bad one are read too
    assert _same(r, read_bag(bad, fast=False))


def test_damaged_sqlite_and_ros1(tmp_path):
    """
    A cut sqlite3 or ROS 1 bag gives its readable messages (original values) and a warning.

    rosbags refuses both (SQLite sees a malformed image, ROS 1 needs the index at the end);
    the direct readers salvage the complete pages / chunks, on the fast and generic paths.
    """
    s = _samples(6000)
    db = tmp_path / 'sq'
    write_imu_bag(db, s, storage='sqlite3')
    bag = tmp_path / 'r.bag'
    write_imu_bag(bag, s, storage='ros1')
    cut = tmp_path / 'cut.db3'
    raw = (db / 'sq.db3').read_bytes()
    cut.write_bytes(raw[:len(raw) // 2])
    cut1 = tmp_path / 'cut.bag'
    raw = bag.read_bytes()
    cut1.write_bytes(raw[:len(raw) // 2])
    for path, word in ((cut, 'damaged sqlite3 file'), (cut1, 'truncated')):
        got = []
        for fast in (True, False):
            r = read_bag(path, fast=fast)
            assert 1000 < r.n < 6000, (path, r.n)
            assert any(word in w for w in r.warnings), r.warnings
            assert np.all(np.diff(r.t) > 0)
            idx = np.searchsorted(s.t, r.t)
            assert np.array_equal(r.data, s.data[idx])  # nothing garbled, only rows lost
            got.append(r)
        assert _same(got[0], got[1])
    tiny = tmp_path / 'tiny.bag'
    tiny.write_bytes(raw[:300])
    for fast in (True, False):
        with pytest.raises(InputError, match='damaged ROS 1 bag, no Imu data readable'):
            read_bag(tiny, fast=fast)
    folder = tmp_path / 'garbage_folder'
    shutil.copytree(db, folder)
    (folder / 'sq.db3').write_bytes(os.urandom(3000))
    for fast in (True, False):
        with pytest.raises(InputError, match='garbage_folder: '):
            read_bag(folder, fast=fast)
    (folder / 'sq.db3').unlink()
    with pytest.raises(InputError, match='storage file missing'):
        read_bag(folder)


# ------------------------------------------------------------------------------------- copy


@needs_data
@pytest.mark.parametrize('src', ['jackal_test2_mcap', 'jackal_test2_sqlite3', 'test2.bag'])
def test_copy_bag_with_denoised_topic(tmp_path, src):
    """The analyze --denoise output: all original topics plus the new Imu topic, readable."""
    orig = read_bag(DATA / src)
    den = Samples(t=orig.t, data=orig.data * 0.5)
    out = tmp_path / 'with_denoised'
    copy_bag_with_topic(DATA / src, out, '/imu/data_denoised', den, frame_id='base_link')
    assert (out / 'with_denoised.mcap').exists()
    topics = bag_topics(out)
    assert topics['/imu/data'] == ('sensor_msgs/msg/Imu', 3061)
    assert topics['/jackal_velocity_controller/odom'] == ('nav_msgs/msg/Odometry', 3060)
    assert topics['/imu/data_denoised'] == ('sensor_msgs/msg/Imu', 3061)
    for fast in (True, False):
        assert _same(read_bag(out, topic='/imu/data', fast=fast), orig)
        d = read_bag(out, topic='/imu/data_denoised', fast=fast)
        assert np.array_equal(d.data, den.data) and np.max(np.abs(d.t - orig.t)) < 1e-9
    # The copied odometry still deserializes (ROS 1 sources are migrated to ROS 2 types).
    from rosbags.highlevel import AnyReader
    with AnyReader([out]) as reader:
        conns = [c for c in reader.connections if c.msgtype == 'nav_msgs/msg/Odometry']
        first = next(reader.messages(connections=conns))
        odom = reader.deserialize(first[2], first[0].msgtype)
        assert odom.header.stamp.sec == 47
        assert not hasattr(odom.header, 'seq')
    with pytest.raises(InputError, match='already exists'):
        copy_bag_with_topic(DATA / src, tmp_path / 'x', '/imu/data', den)


def big_message_bag(tmp_path, storage):
    """
    Write 3000 Imu samples with a large String every 100 (SQLite overflow pages).

    Returns (path, samples).
    """
    s = _samples(3000)
    ts = get_typestore(Stores.ROS1_NOETIC if storage == 'ros1' else Stores.ROS2_JAZZY)
    text = ts.types['std_msgs/msg/String']
    big = [(int(ns), text(data='x' * (5000 + 37 * i)))
           for i, ns in enumerate((s.t[::100] * 1e9).astype(np.int64))]
    path = tmp_path / ('b.bag' if storage == 'ros1' else 'b')
    write_imu_bag(path, s, storage=storage,
                  extra_topics={'/log': ('std_msgs/msg/String', big)})
    return path, s


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap', 'ros1'])
def test_big_messages_between_imu_messages(tmp_path, storage):
    """Large non-Imu messages (SQLite overflow pages, long records) do not disturb the Imu."""
    path, s = big_message_bag(tmp_path, storage)
    fast = read_bag(path)
    assert _same(fast, read_bag(path, fast=False))
    assert fast.n == 3000 and np.array_equal(fast.data, s.data)


def test_write_bag_with_second_imu_samples(tmp_path):
    """extra_topics accepts Samples: the analyze --denoise output for non-bag inputs."""
    s = _samples(400)
    den = Samples(t=s.t, data=s.data[:, :3] * 0.5, axes=('gyro_x', 'gyro_y', 'gyro_z'))
    path = tmp_path / 'den'
    write_imu_bag(path, s, topic='imu/data_raw', extra_topics={'imu/data_denoised': den})
    assert sorted(list_imu_topics(path)) == ['imu/data_denoised', 'imu/data_raw']
    raw = read_bag(path, topic='imu/data_raw')
    d = read_bag(path, topic='imu/data_denoised', fast=False)
    assert np.array_equal(raw.data, s.data)
    assert np.array_equal(d.data[:, :3], den.data) and not d.data[:, 3:].any()


def damaged_copies(raw, seed, count, first=0):
    """
    Yield ``count`` seeded damaged copies of the bytes ``raw``.

    Every fourth is cut at a random length; the others get 1-3 random runs of 1-63 random bytes
    at positions from ``first`` on (``first`` = 4096 spares an SQLite file's header page).
    """
    rng = np.random.default_rng(seed)
    for k in range(count):
        data = bytearray(raw)
        if k % 4 == 3:
            data = data[:int(rng.integers(1, len(data)))]
        else:
            for _ in range(1 + k % 3):
                at = int(rng.integers(first, len(data) - 64))
                size = int(rng.integers(1, 64))
                data[at:at + size] = rng.bytes(size)
        yield bytes(data)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
def test_random_damage_gives_samples_or_input_error(tmp_path, storage):
    """
    Overwrite random byte ranges or cut the file: never a traceback, only InputError or data.

    16 seeded variants per storage (overwrites of 1-63 bytes at 1-3 places, or a cut), each
    read on both paths. Damage inside a message's numbers cannot be detected (rosbags writes
    no checksums), so only the outcome type is checked here.
    """
    s = _samples(8000)  # 3 chunks of MCAP and ROS 1, 700 SQLite pages
    path = tmp_path / ('good.bag' if storage == 'ros1' else 'good')
    write_imu_bag(path, s, storage=storage, compress=storage == 'mcap')
    f = path if storage == 'ros1' else next(path.glob('good.*'))
    raw = f.read_bytes()
    outcomes = {'samples': 0, 'error': 0}
    for k, data in enumerate(damaged_copies(raw, seed=11, count=16)):
        bad = tmp_path / f'bad{k}{f.suffix}'
        bad.write_bytes(data)
        for fast in (True, False):
            try:
                r = read_bag(bad, fast=fast)
            except InputError as err:
                assert str(err).startswith(str(bad)) and '\n' not in str(err)
                outcomes['error'] += 1
            else:
                assert r.n > 0 and r.data.shape == (r.n, 6)
                outcomes['samples'] += 1
    assert outcomes['samples'] > 0  # most damage leaves something readable
