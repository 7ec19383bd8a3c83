"""Split tables: shares, nesting, disjointness, holdouts, determinism, errors."""

import math

import pandas as pd
import pytest

from conftest import CWRU, DATA_FOLDERS, ROOT
from condmon.report.calibration_set import calibration_summary
from condmon.hybrid import (
    SPLIT_COLUMNS,
    SplitError,
    calibration_frame,
    measured_layout,
    n_train_records,
    read_split_table,
    time_blocks,
    write_split_table,
)
from condmon.protocols import PROTOCOLS, check_healthy_tested, make_splits, protocol_from
from condmon.labels import sorted_holdouts
from condmon.systems.bearing.cwru import cwru_rows

HEALTH = ("healthy", "surface_fault", "missing_tooth")
SPEEDS = (450.0, 775.0, 1100.0)
PERCENTS = [0, 10, 25, 50, 75, 100]


def make_records(n_per_stratum=10, lonely=True):
    """n records per (health, speed) stratum; optionally one stratum with a single record."""
    rows = [
        (f"{h}_{int(s)}_{i:02d}", h, s)
        for h in HEALTH
        for s in SPEEDS
        for i in range(n_per_stratum)
    ]
    if lonely:
        rows.append(("crack_775_00", "crack", 775.0))
    return pd.DataFrame(rows, columns=["record_id", "health_state", "speed_rpm"])


RECORDS = make_records()
STRATUM = RECORDS.set_index("record_id")[["health_state", "speed_rpm"]].apply(tuple, axis=1)


def train_sets(splits):
    """{(percent, repeat, holdout): set of training record ids}."""
    return {
        key: set(group.record_id[group.role == "train"])
        for key, group in splits.groupby(["measured_percent", "repeat", "holdout"])
    }


def test_columns_and_types():
    splits = make_splits(RECORDS, "record_split", measured_percent=[0, 50], repeats=2, seed=1)
    assert list(splits.columns) == SPLIT_COLUMNS
    assert str(splits.measured_percent.dtype) == "int32"
    assert str(splits.repeat.dtype) == "int32"
    assert set(splits.protocol) == {"record_split"}
    assert set(splits.holdout) == {""}
    assert set(splits.role) <= {"train", "test"}


def test_every_record_once_per_split_and_never_on_both_sides():
    splits = make_splits(RECORDS, "record_split", measured_percent=PERCENTS, repeats=3, seed=7)
    for _, group in splits.groupby(["measured_percent", "repeat", "holdout"]):
        assert sorted(group.record_id) == sorted(RECORDS.record_id)
        train = set(group.record_id[group.role == "train"])
        test = set(group.record_id[group.role == "test"])
        assert not train & test


@pytest.mark.parametrize("min_test", [1, 2])
def test_record_split_shares_per_stratum(min_test):
    splits = make_splits(
        RECORDS,
        "record_split",
        measured_percent=PERCENTS,
        repeats=2,
        seed=3,
        min_test_records=min_test,
    )
    splits = splits.assign(stratum=splits.record_id.map(STRATUM))
    for (percent, _, stratum), group in splits.groupby(["measured_percent", "repeat", "stratum"]):
        n = len(group)
        expected = max(0, min(math.floor(percent / 100 * n + 0.5), n - min_test))
        assert (group.role == "train").sum() == expected, (percent, stratum)
    at_100 = splits[(splits.measured_percent == 100) & (splits.repeat == 0)]
    per_stratum_test = at_100[at_100.role == "test"].groupby("stratum").size()
    assert (per_stratum_test[per_stratum_test.index != ("crack", 775.0)] == min_test).all()
    assert per_stratum_test[("crack", 775.0)] == 1  # a single record always stays in test


def test_n_train_records_rounds_half_up_and_caps():
    assert n_train_records(10, 25, 1) == 3  # 2.5 -> 3
    assert n_train_records(10, 24, 1) == 2  # 2.4 -> 2
    assert n_train_records(10, 100, 1) == 9
    assert n_train_records(10, 100, 0) == 10
    assert n_train_records(1, 100, 1) == 0
    assert n_train_records(1, 100, 3) == 0


@pytest.mark.parametrize("protocol", ["record_split", "condition_holdout"])
def test_training_sets_are_nested_across_percentages(protocol):
    splits = make_splits(RECORDS, protocol, measured_percent=PERCENTS, repeats=3, seed=11)
    sets = train_sets(splits)
    for (percent, repeat, holdout), train in sets.items():
        for higher in PERCENTS:
            if higher > percent:
                assert train <= sets[(higher, repeat, holdout)], (percent, higher, repeat)
    assert all(not train for (p, _, _), train in sets.items() if p == 0)


def test_condition_holdout_tests_a_whole_speed_and_never_trains_on_it():
    splits = make_splits(RECORDS, "condition_holdout", measured_percent=PERCENTS, repeats=2, seed=5)
    speed = splits.record_id.map(RECORDS.set_index("record_id").speed_rpm)
    assert sorted_holdouts(splits.holdout) == ["speed_rpm=450", "speed_rpm=775", "speed_rpm=1100"]
    for (percent, repeat, holdout), group in splits.assign(speed=speed).groupby(
        ["measured_percent", "repeat", "holdout"]
    ):
        held_out = float(holdout.split("=")[1])
        assert set(group.speed[group.role == "test"]) == {held_out}
        assert (group.role[group.speed == held_out] == "test").all()
        assert held_out not in set(group.speed[group.role == "train"])
        others = group[group.speed != held_out]
        assert set(others.role) <= {"train", "unused"}
        if percent == 100:
            assert (others.role == "train").all()  # nothing of the other speeds held back


def test_same_seed_same_splits_other_seed_other_splits():
    one = make_splits(RECORDS, "record_split", measured_percent=[50], repeats=2, seed=42)
    again = make_splits(
        RECORDS.sample(frac=1, random_state=0),
        "record_split",
        measured_percent=[50],
        repeats=2,
        seed=42,
    )  # input row order must not matter
    pd.testing.assert_frame_equal(one, again)
    other = make_splits(RECORDS, "record_split", measured_percent=[50], repeats=2, seed=43)
    assert train_sets(one) != train_sets(other)
    sets = train_sets(one)
    assert sets[(50, 0, "")] != sets[(50, 1, "")]  # repeats differ


def test_a_new_stratum_does_not_reshuffle_the_others():
    extra = pd.DataFrame(
        {"record_id": [f"aaa_{i}" for i in range(5)], "health_state": "aaa", "speed_rpm": 450.0}
    )
    before = train_sets(
        make_splits(RECORDS, "record_split", measured_percent=[50], repeats=1, seed=2)
    )
    after = train_sets(
        make_splits(
            pd.concat([RECORDS, extra]), "record_split", measured_percent=[50], repeats=1, seed=2
        )
    )
    assert after[(50, 0, "")] - {f"aaa_{i}" for i in range(5)} == before[(50, 0, "")]


def test_same_records_train_in_both_protocols():
    same = dict(measured_percent=[50], repeats=1, seed=9)
    split = train_sets(make_splits(RECORDS, "record_split", **same))
    holdout = train_sets(make_splits(RECORDS, "condition_holdout", **same))
    # The single-record stratum differs by design: record_split keeps it for testing,
    # condition_holdout (tested on another speed) may train on it.
    not_450 = {rid for rid in split[(50, 0, "")] if STRATUM[rid][1] != 450.0}
    held_450 = holdout[(50, 0, "speed_rpm=450")]
    assert held_450 - {"crack_775_00"} == not_450
    assert "crack_775_00" in held_450


def test_per_segment_rows_are_accepted():
    per_segment = pd.concat([RECORDS, RECORDS, RECORDS])
    same = dict(measured_percent=[25], repeats=1, seed=0)
    pd.testing.assert_frame_equal(
        make_splits(per_segment, "record_split", **same),
        make_splits(RECORDS, "record_split", **same),
    )


@pytest.mark.parametrize(
    "percents, culprit",
    [
        ([10, 101], "101"),
        ([-5], "-5"),
        ([12.5], "12.5"),
        (["fifty"], "fifty"),
        ([10, 10], r"\[10\]"),
        ([], "empty"),
    ],
)
def test_bad_percentages_are_named(percents, culprit):
    with pytest.raises(SplitError, match=culprit):
        make_splits(RECORDS, "record_split", measured_percent=percents, repeats=1, seed=0)


def test_unknown_protocol_lists_the_allowed_ones():
    with pytest.raises(SplitError, match=r"'segment_shuffle'.*record_split.*condition_holdout"):
        make_splits(RECORDS, "segment_shuffle", measured_percent=[10], repeats=1, seed=0)


def test_condition_holdout_needs_two_speeds():
    one_speed = RECORDS[RECORDS.speed_rpm == 775.0]
    with pytest.raises(SplitError, match=r"only speed_rpm \['775'\]"):
        make_splits(one_speed, "condition_holdout", measured_percent=[10], repeats=1, seed=0)


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        (dict(repeats=0), "repeats"),
        (dict(seed=-1), "seed"),
        (dict(min_test_records=-1), "min_test"),
    ],
)
def test_bad_integers_are_named(kwargs, culprit):
    settings = dict(repeats=1, seed=0, min_test_records=1)
    settings.update(kwargs)
    with pytest.raises(SplitError, match=culprit):
        make_splits(RECORDS, "record_split", measured_percent=[10], **settings)


def test_record_with_two_labels_is_named():
    bad = pd.concat(
        [
            RECORDS,
            pd.DataFrame(
                [{"record_id": "healthy_450_00", "health_state": "crack", "speed_rpm": 450.0}]
            ),
        ]
    )
    with pytest.raises(SplitError, match="healthy_450_00"):
        make_splits(bad, "record_split", measured_percent=[10], repeats=1, seed=0)


def test_split_table_roundtrip(tmp_path):
    splits = make_splits(RECORDS, "condition_holdout", measured_percent=[0, 50], repeats=2, seed=1)
    path = tmp_path / "hybrid" / "condition_holdout.parquet"
    write_split_table(splits, path)
    pd.testing.assert_frame_equal(read_split_table(path), splits)


# -- protocols of the bearing study: segment_share, unseen_fault, load as the condition --------
def bearing_segments():
    """Two loads x (normal, inner_race, outer_race), one record each, 10 segments per record."""
    rows = [
        (f"{h}-{load}", seg, h, 1797.0 - 25 * load + (h == "normal"), float(load))
        for h in ("normal", "inner_race", "outer_race")
        for load in (0, 1)
        for seg in range(10)
    ]
    return pd.DataFrame(rows, columns=["record_id", "segment", "health_state", "speed_rpm", "load"])


def test_segment_share_splits_segments_per_class():
    segments = bearing_segments()
    splits = make_splits(
        segments, "segment_share", measured_percent=[0, 30, 100], repeats=2, seed=4
    )
    assert list(splits.columns) == SPLIT_COLUMNS and (splits.segment >= 0).all()
    per_class = splits.merge(segments[["record_id", "segment", "health_state"]])
    for (percent, _, health), group in per_class.groupby(
        ["measured_percent", "repeat", "health_state"]
    ):
        assert len(group) == 20  # every segment of the class once
        n_train = (group.role == "train").sum()
        assert n_train == min(math.floor(percent / 100 * 20 + 0.5), 19)  # one segment tests
    train = train_sets(splits.assign(record_id=splits.record_id + "#" + splits.segment.astype(str)))
    assert train[(30, 0, "")] <= train[(100, 0, "")]  # nested shares
    assert train[(30, 0, "")] != train[(30, 1, "")]  # repeats draw differently


def test_unseen_fault_trains_only_measured_classes():
    records = pd.DataFrame(
        [(f"{h}-{i}", h, 1797.0) for h in ("normal", "ball", "inner_race") for i in range(4)],
        columns=["record_id", "health_state", "speed_rpm"],
    )
    splits = make_splits(
        records,
        "unseen_fault",
        measured_percent=[0, 50, 100],
        repeats=1,
        seed=0,
        measured_classes=["normal"],
    )
    health = splits.record_id.str.split("-").str[0]
    assert set(splits.role) <= {"train", "test"}
    assert (splits.role[health != "normal"] == "test").all()
    trained = splits[splits.role == "train"].groupby("measured_percent").size()
    assert trained.get(0, 0) == 0 and trained[50] == 2 and trained[100] == 4
    with pytest.raises(SplitError, match="measured_classes"):
        make_splits(records, "unseen_fault", measured_percent=[0], repeats=1, seed=0)


def test_condition_holdout_by_load():
    segments = bearing_segments()
    splits = make_splits(
        segments, "condition_holdout", measured_percent=[100], repeats=1, seed=0, condition="load"
    )
    assert sorted(set(splits.holdout)) == ["load=0", "load=1"]
    held = splits[splits.holdout == "load=1"]
    assert set(held.record_id[held.role == "test"]) == {"normal-1", "inner_race-1", "outer_race-1"}
    assert set(held.record_id[held.role == "train"]) == {"normal-0", "inner_race-0", "outer_race-0"}
    # per-record speeds differ within a load: strata by load keep one stratum per class and load
    split = make_splits(
        segments, "record_split", measured_percent=[0], repeats=1, seed=0, condition="load"
    )
    assert (split.role == "test").all() and split.record_id.nunique() == 6


# -- honest evaluation: calibration set, healthy test data, whole specimens -----------------------
RESERVE = {"records": [], "calibration_segments": 4, "guard_segments": 1, "blocks": 2}


def with_healthy(protocol, segments, reserve=None, segment_samples=None, **offered):
    """The splits of the bearing study's settings; each protocol takes the parameters of
    `offered` it knows (specimens, condition_split), as the hybrid rule's script does."""
    chosen = protocol_from(
        protocol,
        dict(
            measured_percent=[0, 30, 60, 100],
            repeats=2,
            seed=5,
            condition="load",
            measured_classes=["normal"],
            healthy_state="normal",
            **offered,
        ),
    )
    return make_splits(segments, chosen, reserve=reserve, segment_samples=segment_samples)


def test_a_lone_healthy_record_is_split_in_time_with_guard_gaps():
    units, roles = time_blocks("n", 14, 4, 1, 2)
    assert roles == ["calibration"] * 4 + ["unused"] + [""] * 4 + ["unused"] + [""] * 4
    assert units[5:9] == ["n@block0"] * 4 and units[10:] == ["n@block1"] * 4
    units, roles = time_blocks("n", 15, 4, 1, 2)
    assert roles[-1] == "unused"  # left over at the end
    with pytest.raises(SplitError, match="calibration.reserve: record 'n' has 6 segments"):
        time_blocks("n", 6, 4, 1, 2)


def test_reserved_records_calibrate_whole_and_never_join_a_split():
    segments = bearing_segments()
    layout = measured_layout(segments, "normal", "load", dict(RESERVE, records=["normal-1"]))
    assert set(layout.record_id[layout.fixed_role == "calibration"]) == {"normal-1"}
    splits = with_healthy("record_split", segments, reserve=dict(RESERVE, records=["normal-1"]))
    assert set(splits.role[splits.record_id == "normal-1"]) == {"calibration"}
    with pytest.raises(SplitError, match=r"reserve.records: \['inner_race-0'\] are not 'normal'"):
        measured_layout(segments, "normal", "load", dict(RESERVE, records=["inner_race-0"]))
    with pytest.raises(SplitError, match=r"reserve.records: \['nope'\] are not measured"):
        measured_layout(segments, "normal", "load", dict(RESERVE, records=["nope"]))


def test_of_several_healthy_records_per_condition_the_first_calibrates():
    segments = bearing_segments()
    second = segments[segments.record_id == "normal-0"].assign(record_id="normal-0b")
    layout = measured_layout(pd.concat([segments, second]), "normal", "load", RESERVE)
    calibrating = layout[layout.fixed_role == "calibration"]
    assert calibrating.groupby("record_id").size().to_dict() == {"normal-0": 10}  # whole
    # load 1's lone record is never cut in time: its healthy data test away from calibration
    assert set(layout.unit[layout.record_id == "normal-1"]) == {"normal-1"}
    assert set(layout.fixed_role[layout.record_id == "normal-1"]) == {""}


def test_with_each_condition_every_lone_healthy_record_is_split_in_time():
    """A rig whose segments are taken against each condition's own calibration data (the gear
    rigs' healthy reference) with one healthy record per condition: every condition's record
    gives its calibration block and test blocks, no record calibrates whole; a condition with
    several healthy records still calibrates on its first, whole."""
    segments = bearing_segments()  # one healthy record at each of loads 0 and 1
    layout = measured_layout(segments, "normal", "load", dict(RESERVE, each_condition=True))
    for record in ("normal-0", "normal-1"):
        own = layout[layout.record_id == record]
        assert (own.fixed_role == "calibration").sum() == 4
        assert set(own.unit[own.fixed_role == ""]) == {f"{record}@block0", f"{record}@block1"}
    splits = with_healthy("record_split", segments, reserve=dict(RESERVE, each_condition=True))
    tested = splits[(splits.role == "test") & splits.record_id.str.startswith("normal")]
    assert set(tested.record_id.str.split("@").str[0]) == {"normal-0", "normal-1"}
    second = segments[segments.record_id == "normal-0"].assign(record_id="normal-0b")
    table = pd.concat([segments, second])
    layout = measured_layout(table, "normal", "load", dict(RESERVE, each_condition=True))
    calibrating = layout[layout.fixed_role == "calibration"].groupby("record_id").size()
    assert calibrating.to_dict() == {"normal-0": 10, "normal-1": 4}
    # the report states it (summary.json `calibration_set`)
    assert calibration_summary(layout) == {
        "whole": ["normal-0"],
        "split_in_time": {"normal-1": "4 of 10 segments calibrate, 2 time blocks test"},
    }


def test_healthy_records_calibrate_per_condition_and_leave_one_to_test():
    """`reserve.healthy_records` of several healthy records per condition calibrate, never all."""
    segments = bearing_segments()
    copies = [
        segments[segments.record_id == "normal-0"].assign(record_id=f"normal-0{c}") for c in "bc"
    ]
    table = pd.concat([segments] + copies)
    for wanted, expected in ((2, {"normal-0", "normal-0b"}), (5, {"normal-0", "normal-0b"})):
        layout = measured_layout(table, "normal", "load", dict(RESERVE, healthy_records=wanted))
        assert (
            set(layout.record_id[layout.fixed_role == "calibration"]) == expected
        )  # normal-0c tests
        assert set(layout.fixed_role[layout.record_id == "normal-0c"]) == {""}


def test_with_one_healthy_record_per_load_one_calibrates_and_the_others_test():
    """CWRU's full set has one healthy record per load: the calibration takes one whole, the
    others are whole split units, so every healthy test segment is of a record the calibration
    never saw (cutting each in time would test beside its own calibration block)."""
    segments = bearing_segments()  # normal-0 (load 0), normal-1 (load 1)
    layout = measured_layout(segments, "normal", "load", RESERVE)
    assert set(layout.record_id[layout.fixed_role == "calibration"]) == {"normal-0"}
    assert (layout.unit == layout.record_id).all()
    for protocol in ("unseen_fault", "record_split", "condition_holdout"):
        splits = with_healthy(protocol, segments, reserve=RESERVE)
        assert set(splits.role[splits.record_id == "normal-0"]) == {"calibration"}
        assert set(splits.record_id[splits.segment >= 0]) <= {"normal-0"}  # its calibration rows
        tested = splits[(splits.role == "test") & (splits.record_id == "normal-1")]
        assert len(tested.groupby(["measured_percent", "repeat", "holdout"])) == len(
            splits.groupby(["measured_percent", "repeat", "holdout"])
        )


def test_a_guard_gap_shorter_than_a_segment_is_refused():
    """Overlapping segments: the guard gap between a lone healthy record's calibration block and
    its next block must hold one segment length of samples."""
    segments = bearing_segments()
    segments = segments[segments.record_id != "normal-1"]  # one healthy record: cut in time
    # 50 % overlap (2048 every 1024): one guard segment leaves 0 samples, three leave 2048
    with pytest.raises(SplitError, match=r"guard gap of 0 samples .* guard_segments >= 3"):
        with_healthy("record_split", segments, reserve=RESERVE, segment_samples=(2048, 1024))
    with pytest.raises(SplitError, match=r"guard gap of 1024 samples"):
        with_healthy(
            "record_split",
            segments,
            reserve=dict(RESERVE, guard_segments=2, calibration_segments=2),
            segment_samples=(2048, 1024),
        )
    splits = with_healthy(
        "record_split",
        segments,
        reserve=dict(RESERVE, guard_segments=3, calibration_segments=2, blocks=2),
        segment_samples=(2048, 1024),
    )
    unused = splits[(splits.record_id == "normal-0") & (splits.role == "unused")]
    assert {2, 3, 4} <= set(unused.segment)
    # no overlap: one guard segment is one segment length
    with_healthy("record_split", segments, reserve=RESERVE, segment_samples=(4096, 4096))


def test_a_split_without_healthy_test_data_is_an_error():
    segments = bearing_segments()
    # unseen_fault at 100 %: every healthy record would train; with healthy_state one stays back
    splits = with_healthy("unseen_fault", segments)
    tested = splits[(splits.role == "test") & splits.record_id.str.startswith("normal")]
    assert len(tested.groupby(["measured_percent", "repeat"])) == 8
    split = pd.DataFrame(
        {
            "protocol": "p",
            "measured_percent": [0],
            "repeat": [0],
            "holdout": [""],
            "record_id": ["inner_race-0"],
            "segment": [-1],
            "role": ["test"],
        }
    )
    with pytest.raises(SplitError, match=r"\(0, 0, ''\) of protocol 'p' tests no 'normal' data"):
        check_healthy_tested(
            split, pd.DataFrame({"record_id": ["normal-0"], "health_state": ["normal"]}), "normal"
        )


def test_condition_holdout_tests_healthy_data_of_another_load_where_the_held_out_has_none():
    segments = bearing_segments()
    segments = segments[segments.record_id != "normal-1"]
    splits = with_healthy("condition_holdout", segments)
    load1 = splits[splits.holdout == "load=1"]
    for _, split in load1.groupby(["measured_percent", "repeat"]):
        assert "test" in set(split.role[split.record_id == "normal-0"])


@pytest.fixture(scope="module")
def shared_cwru():
    if not CWRU.is_dir():
        pytest.skip(f"CWRU data folder {CWRU} not present")
    ingest = cwru_rows(CWRU, task="location")
    segments = pd.DataFrame(ingest.rows)[["record_id", "segment", "health_state", "load"]]
    return segments.drop_duplicates(["record_id", "segment"]), ingest.records


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_shared_cwru_splits_are_honest(shared_cwru, protocol):
    """The splits of the shared CWRU files: no calibration segment in any test (or training)
    set, healthy data in every test set, calibration and test segments apart by a guard gap,
    and under specimen_holdout no fault specimen on both sides."""
    segments, records = shared_cwru
    calibration = calibration_frame(segments, "normal", "load", RESERVE)
    assert set(calibration.record_id) == {"cwru-97"} and list(calibration.segment) == [0, 1, 2, 3]
    splits = with_healthy(protocol, segments, reserve=RESERVE, specimens=records)
    specimen = dict(zip(records.record_id, records.specimen))
    calibrating = set(zip(calibration.record_id, calibration.segment))
    for key, split in splits.groupby(["measured_percent", "repeat", "holdout"]):
        roles = split.groupby("role")
        test, train = roles.get_group("test"), split[split.role == "train"]
        pairs = set(zip(test.record_id, test.segment)) | set(zip(train.record_id, train.segment))
        assert not pairs & calibrating, key
        assert set(
            split.role[split.segment.isin([0, 1, 2, 3]) & (split.record_id == "cwru-97")]
        ) == {"calibration"}
        healthy_test = test[test.record_id == "cwru-97"]
        assert len(healthy_test), key  # false alarms are measured in every split
        assert healthy_test.segment.min() > 4  # guard gap after the calibration block
        if protocol != "segment_share":  # whole records (or time blocks) per side
            assert not set(test.record_id) & set(train.record_id) - {"cwru-97"}, key
        if protocol == "specimen_holdout":
            assert not {specimen[r] for r in test.record_id} & {
                specimen[r] for r in train.record_id
            }
            held = key[2].partition("=")[2]
            assert set(
                records.set_index("record_id").loc[
                    test.record_id[test.record_id != "cwru-97"].unique(), "specimen_group"
                ]
            ) == {held}


def test_design_records_are_reported_apart_on_the_shared_files(shared_cwru):
    """config/cwru.yaml's design specimens (cwru.design_specimens) cover every shared record's
    specimen, and nothing else of a full download but the same bearings at other loads; a folder
    with other specimens gets their records reported apart. Simulated here by declaring the
    load-0 records only: the `design` rows hold exactly the tested load-0 records, the
    `evaluation` rows the load-1 ones."""
    from conftest import system_of
    from condmon.evaluation import evaluation_table, summarise
    from condmon.systems.bearing.cwru import CWRU_TABLE, specimen_of

    segments, records = shared_cwru
    design = set(system_of("config/cwru.yaml").design_specimens())
    assert set(records.specimen) == design
    # in the whole catalogue: the same ten bearings at the four loads, no other specimen
    designed = CWRU_TABLE[
        [specimen_of(row)["specimen"] in design for _, row in CWRU_TABLE.iterrows()]
    ]
    assert len(designed) == 40 and set(designed.load_hp) == {0.0, 1.0, 2.0, 3.0}
    assert set(records.cwru_number) < set(designed.cwru_number)
    splits = with_healthy("unseen_fault", segments, reserve=RESERVE, specimens=records)
    labels = segments.drop_duplicates("record_id").set_index("record_id")
    tested = splits[splits.role == "test"]
    whole = tested.segment == -1  # a whole record: all its segments
    test = pd.concat(
        [
            tested[whole].drop(columns="segment").merge(segments, on="record_id"),
            tested[~whole].merge(segments, on=["record_id", "segment"]),
        ]
    )
    predictions = test.assign(
        classifier="svm", true_label=test.health_state, predicted_label="normal"
    )  # any rule: the bookkeeping is tested
    conditions = labels["load"].to_dict()
    load0 = sorted(labels.index[labels["load"] == 0])
    table = evaluation_table(
        predictions,
        "normal",
        sorted(set(labels.health_state)),
        conditions,
        "load",
        design_records=load0,
    )
    summary = summarise(table, predictions, "normal", conditions, "load", load0)
    for subset, load in (("design", 0), ("evaluation", 1)):
        rows = table[(table.records == subset) & (table.condition == "all")]
        expected = predictions.groupby(["measured_percent", "repeat"]).apply(
            lambda p: int((p.load == load).sum()), include_groups=False
        )
        assert rows.set_index(["measured_percent", "repeat"]).n_test.to_dict() == expected.to_dict()
        assert set(summary[summary.records == subset].measured_percent) == {0, 30, 60, 100}
    # the healthy record (load 0, a design record) measures false alarms only in `design`
    evaluation_rows = table[table.records == "evaluation"]
    assert (evaluation_rows.n_healthy == 0).all() and (
        table[table.records == "design"].n_healthy > 0
    ).all()


def test_a_fixed_condition_split_on_the_shared_files_and_its_missing_loads(shared_cwru):
    """pdm-bench's cwru_cross_load (train loads 0-2, test load 3) needs loads the shared folder
    lacks: the error names them. Its variant on what exists (train load 0, test load 1): one
    holdout, every load-1 record tests, only load-0 records train, no fault recording on both
    sides (the lone healthy record is split in time: its blocks test at 100 %)."""
    segments, records = shared_cwru
    with pytest.raises(
        SplitError,
        match=r"needs measured records at load \['2', '3'\].*"
        r"have load \['0', '1'\]",
    ):
        with_healthy(
            "condition_holdout",
            segments,
            reserve=RESERVE,
            condition_split={"train": [0, 1, 2], "test": [3]},
        )
    splits = with_healthy(
        "condition_holdout", segments, reserve=RESERVE, condition_split={"train": [0], "test": [1]}
    )
    assert set(splits.holdout) == {"load=1"}
    load = dict(zip(records.record_id, records.load_hp.astype(float)))
    for key, split in splits.groupby(["measured_percent", "repeat"]):
        test = set(split.record_id[split.role == "test"])
        train = set(split.record_id[split.role == "train"])
        assert {r for r in load if load[r] == 1} <= test, key
        assert all(load[r] == 0 for r in train), key
        assert not test & train - {"cwru-97"}, key
        assert "cwru-97" in test, key  # false alarms measured
    full = splits[splits.measured_percent == 100]
    assert set(full.record_id[full.role == "train"]) == {r for r in load if load[r] == 0}


def test_overlapping_windows_of_a_cwru_file():
    """2048-sample windows every 1024 samples (50 % overlap): each window's second half is the
    next one's first half."""
    if not CWRU.is_dir():
        pytest.skip(f"CWRU data folder {CWRU} not present")
    plain = cwru_rows(CWRU, task="location", segment_length=2048, files=["105.mat"])
    half = cwru_rows(
        CWRU, task="location", segment_length=2048, segment_hop=1024, files=["105.mat"]
    )
    n = int(half.records.n_samples.iloc[0])
    assert len(half.rows) == (n - 2048) // 1024 + 1 == int(half.records.n_segments.iloc[0])
    assert len(plain.rows) == n // 2048
    first, second = half.rows[0]["signal"], half.rows[1]["signal"]
    assert (first[1024:] == second[:1024]).all()
    assert (half.rows[2]["signal"] == plain.rows[1]["signal"]).all()
    with pytest.raises(ValueError, match="segment_hop must lie in 1..segment_length"):
        cwru_rows(CWRU, segment_length=2048, segment_hop=4096, files=["105.mat"])


def test_the_pdm_bench_config_asks_for_its_split_and_checks_the_guard_gap():
    import yaml
    from condmon.config import ConfigError, load_schema, validate_config

    schema = load_schema(ROOT / "config/schema.yaml")
    raw = yaml.safe_load((ROOT / "config/cwru-pdm-bench.yaml").read_text())
    raw.update(
        {key: str(folder) for key, folder in DATA_FOLDERS.items() if key in raw}
    )  # this machine's copy
    config = validate_config(raw, schema)
    assert config["hybrid"]["condition_split"] == {"train": [0, 1, 2], "test": [3]}
    assert (config["bearing"]["segment_length"], config["bearing"]["segment_hop"]) == (2048, 1024)
    assert config["hybrid"]["protocols"] == ["condition_holdout"]
    assert config["calibration"]["reserve"]["guard_segments"] == 3  # 2048 samples of gap
    raw["bearing"]["segment_hop"] = 512  # 75 % overlap: three guard segments leave 512 samples
    with pytest.raises(
        ConfigError,
        match="guard_segments 3 leaves a guard gap shorter than one "
        r"segment .* use at least 7",
    ):
        validate_config(raw, schema)
