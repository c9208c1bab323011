"""analyze's export options: parsed into one ExportOptions, and what it asks the record for."""

from argparse import Namespace

from imu_allan.cli.analyze import _options, build_parser
from imu_allan.cli.export_args import export_options, parse_inflate, parse_names
from imu_allan.errors import InputError
from imu_allan.report.exporters import EXPORTERS
import pytest


def test_parse_names_and_inflate():
    assert parse_names('all') == list(EXPORTERS)
    assert parse_names('vins, kalibr,vins') == ['vins', 'kalibr']
    with pytest.raises(InputError, match="unknown exporter 'nosuch'"):
        parse_names('kalibr,nosuch')
    assert parse_inflate('2') == (2.0, 2.0) and parse_inflate('2,10') == (2.0, 10.0)
    for bad in ('0', '-1', 'x', '1,2,3', '1e9', 'nan'):
        with pytest.raises(InputError, match='--inflate'):
            parse_inflate(bad)


def test_export_options_and_the_overbounds_they_ask_for():
    """One named object; --overbound asks the record for each consumer model once."""
    args = build_parser().parse_args(['x.csv', '--out', 'o', '--export', 'kalibr,vins,px4,gazebo',
                                      '--inflate', '2,10', '--overbound',
                                      '--overbound-horizon', '20'])
    exports = export_options(args)
    assert exports.names == ('kalibr', 'vins', 'px4', 'gazebo')
    assert exports.inflate == (2.0, 10.0) and exports.overbound and exports.horizon_s == 20.0
    request = _options(args).overbound
    assert request.horizon_s == 20.0
    # kalibr and vins share one model; PX4 has one set of values per sensor (the envelope)
    assert request.models == ((EXPORTERS['kalibr'].model, 'axis'),
                              (EXPORTERS['px4'].model, 'sensor'),
                              (EXPORTERS['gazebo'].model, 'axis'))
    plain = build_parser().parse_args(['x.csv', '--out', 'o', '--export', 'kalibr'])
    assert export_options(plain).overbound_request() is None
    assert _options(plain).overbound is None


def test_export_options_need_their_companions():
    """--overbound without --export, a horizon without --overbound: one InputError each."""
    for argv, option in ((['x.csv', '--overbound'], '--overbound'),
                         (['x.csv', '--out', 'o', '--export', 'kalibr', '--overbound-horizon',
                           '5'], '--overbound-horizon')):
        with pytest.raises(InputError, match=option):
            _options(build_parser().parse_args(argv))
    assert export_options(Namespace(export=None, inflate=(1.0, 1.0), overbound=False,
                                    overbound_horizon=None)).names == ()
