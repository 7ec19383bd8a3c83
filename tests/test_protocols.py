"""The protocols as splitter objects: the registry, the reasons, the split tables as before the
refactor (golden digests), the parameter limit."""

import ast
import hashlib
from pathlib import Path

import pandas as pd
import pytest

from conftest import ROOT
from condmon.hybrid import SPLIT_COLUMNS, SplitError
from condmon.protocols import (
    PROTOCOLS,
    REGISTRY,
    Protocol,
    Split,
    make_protocol,
    make_splits,
    protocol_from,
)
from condmon.protocols.registry import parameters

HEALTH = ("healthy", "surface_fault", "missing_tooth")
SPEEDS = (450.0, 775.0, 1100.0)
RESERVE = {"records": [], "calibration_segments": 4, "guard_segments": 1, "blocks": 2}


def gear_records(n=10, segments=0):
    """n records per (health, speed) stratum, one lone crack record; `segments` rows each."""
    rows = [(f"{h}_{int(s)}_{i:02d}", h, s) for h in HEALTH for s in SPEEDS for i in range(n)]
    rows.append(("crack_775_00", "crack", 775.0))
    frame = pd.DataFrame(rows, columns=["record_id", "health_state", "speed_rpm"])
    if segments:
        frame = frame.merge(pd.DataFrame({"segment": range(segments)}), how="cross")
    return frame


def gear_simulated(n=6, segments=2):
    rows = [
        (f"sim_{h}_{int(s)}_{i:02d}", seg, h, s)
        for h in HEALTH + ("crack",)
        for s in SPEEDS
        for i in range(n)
        for seg in range(segments)
    ]
    return pd.DataFrame(rows, columns=["record_id", "segment", "health_state", "speed_rpm"])


def bearing(healthy_loads=(0, 1, 2), n_segments=14):
    """Loads 0-2; one healthy record per load in `healthy_loads`; three fault classes of three
    sizes (the specimen groups) at every load; `n_segments` segments per record."""
    rows, specimens = [], []
    for load in healthy_loads:
        specimens.append((f"normal-{load}", "normal", ""))
        rows += [(f"normal-{load}", seg, "normal", float(load)) for seg in range(n_segments)]
    for health in ("inner_race", "ball", "outer_race"):
        for size in ("0.007", "0.014", "0.021"):
            for load in (0, 1, 2):
                rid = f"{health}-{size}-{load}"
                specimens.append((rid, f"{health}-{size}", size))
                rows += [(rid, seg, health, float(load)) for seg in range(n_segments)]
    return (
        pd.DataFrame(rows, columns=["record_id", "segment", "health_state", "load"]),
        pd.DataFrame(specimens, columns=["record_id", "specimen", "specimen_group"]),
    )


def bearing_offered(**extra):
    segments, specimens = bearing()
    return dict(
        measured_percent=[0, 30, 60, 100],
        repeats=2,
        seed=5,
        condition="load",
        healthy_state="normal",
        specimens=specimens,
        measured_classes=["normal"],
        **extra,
    )


def case(name):
    """(records, protocol, make_splits keywords) of a golden case."""
    kind, protocol = name.split(":")
    if kind == "gear":
        extra = {"measured_classes": ["healthy"]} if protocol == "unseen_fault" else {}
        records = gear_records(n=4, segments=3) if protocol == "segment_share" else gear_records()
        return (
            records,
            make_protocol(
                protocol,
                measured_percent=[0, 10, 25, 50, 75, 100],
                repeats=1,
                seed=0,
                healthy_state="healthy",
                **extra,
            ),
            {},
        )
    if kind == "gear-simval":
        extra = {"measured_classes": ["healthy"]} if protocol == "unseen_fault" else {}
        return (
            gear_records(n=4, segments=3),
            make_protocol(
                protocol,
                measured_percent=[0, 25, 100],
                repeats=2,
                seed=11,
                healthy_state="healthy",
                **extra,
            ),
            dict(simulated_records=gear_simulated(), simulated_validation_share=0.34),
        )
    if kind == "bearing-reserve":
        return bearing()[0], protocol_from(protocol, bearing_offered()), dict(reserve=RESERVE)
    if kind == "bearing-lone":  # one healthy record: cut in time
        return (
            bearing(healthy_loads=(0,), n_segments=20)[0],
            protocol_from(protocol, bearing_offered()),
            dict(
                reserve=dict(RESERVE, guard_segments=3, calibration_segments=2),
                segment_samples=(2048, 1024),
            ),
        )
    assert kind == "bearing-split"
    return (
        bearing()[0],
        protocol_from(protocol, bearing_offered(condition_split={"train": [0, 1], "test": [2]})),
        dict(reserve=RESERVE),
    )


# sha256 of each case's split table as CSV, computed with make_splits as it was before the
# protocols became objects (commit 3673e3a), the old function fed the same records and parameters
# (its frames equal the new ones, assert_frame_equal): the refactor changed no split
GOLDEN = {
    "gear:record_split": "9253da4921c0ebfabcba9721738f91eb2282db015ee3ffc2e00c6b29e08a0ba0",
    "gear:condition_holdout": "4fa7c5660b2345d3f56d6281a8faaefe16f88faf91f4d72f56319b17bc387472",
    "gear:segment_share": "66d293e50fc2966dc23130897a72e92d3e5eb38ae57c6fba12c3deabab636e3a",
    "gear:unseen_fault": "46d854dd0d052c069ee4e102ec67a32e40d305f19b779212d386049403c52f86",
    "gear-simval:record_split": "eddfcdba8b587b9381cb13cb5cf55180fc30f08e0bcf950c4bd19563b02da5ec",
    "gear-simval:condition_holdout": "177b0dd58cac3bc18e00c594f4bf0aa46a84de0e16fe9e4d7ad372b56ffc596f",
    "gear-simval:segment_share": "e2c9f4f90a22b7ff42c8c3567152382d5fb9d14a117ba86bf9fa83a7232bca30",
    "gear-simval:unseen_fault": "b76a9c0547927456f3d974e2da28a45660a4d4fbc0320d14076104e4076cd3c4",
    "bearing-reserve:record_split": "2967db1e4b9fb961a230dcf7b7faed20cb3ec025dfe1a98ff3b77428fe86ff65",
    "bearing-reserve:condition_holdout": "a24ffa0b31bb292deae50774e2e2ab859e29a95bbb1cb499ee7a731b6649d949",
    "bearing-reserve:segment_share": "71dc232ba4f9dd698c08b86ae72929d38fd8eb5a55f28f0545204f3672b490e6",
    "bearing-reserve:unseen_fault": "f8bb31967c4122f396a7c1486f3e4471de2e0d4808922312c494c52715257093",
    "bearing-reserve:specimen_holdout": "7f2661f926ed0e1db804d3f13954545a7cf881eb9b8cd66f7bc54fc873a16e42",
    "bearing-lone:record_split": "2e8af283fc395ea7a0f2c095fee2a10917f7ad69c050fa810f0b380b407e6ca6",
    "bearing-lone:condition_holdout": "9a42f9878c9ca60a4fff89c399fbebd35e984f1cffb5e0c36a6809c0b65ebb89",
    "bearing-lone:segment_share": "98635f260c8ff6f1399bd6bfdf6cc1d475218374a49f297b2275cbda16239b65",
    "bearing-lone:unseen_fault": "b5d77ef974029c681109ab192b0cd47b6519bc6d96ae79555e9f8690168e10be",
    "bearing-lone:specimen_holdout": "69763def290afce4d0200dff0aaa7d4413e90d2fcc1f36529742ad83896c026a",
    "bearing-split:condition_holdout": "5207229e45349997205549ba0b8d5d1fc9c2d11f6410862edd66a90380fb9273",
}


def digest(splits: pd.DataFrame) -> str:
    return hashlib.sha256(splits.to_csv(index=False).encode()).hexdigest()


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_split_tables_are_those_of_the_code_before_the_registry(name):
    records, protocol, keywords = case(name)
    assert digest(make_splits(records, protocol, **keywords)) == GOLDEN[name]


# -- the registry -----------------------------------------------------------------------------
def test_the_registry_names_every_protocol_by_its_class():
    assert PROTOCOLS == (
        "record_split",
        "condition_holdout",
        "segment_share",
        "unseen_fault",
        "specimen_holdout",
    )
    for name, cls in REGISTRY.items():
        assert cls.name == name and issubclass(cls, Protocol)
        assert parameters(name)[:3] == ("measured_percent", "repeats", "seed")


def test_make_protocol_names_the_valid_protocols_and_parameters():
    with pytest.raises(
        SplitError,
        match=r"'segment_shuffle'; choose one of \['record_split', "
        r"'condition_holdout', 'segment_share'",
    ):
        make_protocol("segment_shuffle", measured_percent=[0], repeats=1, seed=0)
    with pytest.raises(
        SplitError,
        match=r"'record_split' takes no parameter\(s\) "
        r"\['measured_classes'\]; it takes \['measured_percent'",
    ):
        make_protocol(
            "record_split", measured_percent=[0], repeats=1, seed=0, measured_classes=["normal"]
        )
    with pytest.raises(SplitError, match="unseen_fault needs measured_classes"):
        make_protocol("unseen_fault", measured_percent=[0], repeats=1, seed=0)
    with pytest.raises(TypeError, match="go with a protocol name"):
        make_splits(
            gear_records(),
            make_protocol("record_split", measured_percent=[0], repeats=1, seed=0),
            seed=1,
        )


def test_a_new_protocol_is_a_class_and_a_registry_line(monkeypatch):
    class EveryRecordTests(Protocol):
        name = "every_record_tests"

        def assign(self, orders, percent):
            yield "", [(rid, "test", "tests, always") for ids in orders.values() for rid in ids]

    monkeypatch.setitem(REGISTRY, EveryRecordTests.name, EveryRecordTests)
    splits = make_splits(
        gear_records(),
        "every_record_tests",
        measured_percent=[0, 50],
        repeats=2,
        seed=0,
        reasons=True,
    )
    assert set(splits.role) == {"test"} and set(splits.reason) == {"tests, always"}
    assert len(splits) == 4 * len(gear_records())


# -- splits and their reasons -------------------------------------------------------------------
def test_split_yields_one_split_per_share_repeat_and_holdout_with_every_unit_once():
    records = gear_records()
    protocol = make_protocol("condition_holdout", measured_percent=[0, 50], repeats=2, seed=3)
    splits = list(protocol.split(records))
    assert all(isinstance(s, Split) for s in splits)
    assert [(s.measured_percent, s.repeat, s.holdout) for s in splits][:3] == [
        (0, 0, "speed_rpm=450"),
        (0, 0, "speed_rpm=775"),
        (0, 0, "speed_rpm=1100"),
    ]
    assert len(splits) == 2 * 2 * 3
    table = make_splits(records, protocol)
    for split in splits:
        assert sorted(a.record_id for a in split.assignments) == sorted(records.record_id)
        rows = table[
            (table.measured_percent == split.measured_percent)
            & (table.repeat == split.repeat)
            & (table.holdout == split.holdout)
        ]
        assert sorted(split.train) == sorted(rows.record_id[rows.role == "train"])
        assert sorted(split.test) == sorted(rows.record_id[rows.role == "test"])


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_reasons_add_a_column_and_change_no_row(protocol):
    records = bearing()[0]
    chosen = protocol_from(protocol, bearing_offered())
    plain = make_splits(records, chosen, reserve=RESERVE)
    explained = make_splits(records, chosen, reserve=RESERVE, reasons=True)
    assert list(explained.columns) == SPLIT_COLUMNS + ["reason"]
    pd.testing.assert_frame_equal(explained[SPLIT_COLUMNS], plain)
    assert explained.reason.str.len().min() > 10


def test_reasons_say_why_a_record_is_where_it_is():
    records = bearing(healthy_loads=(0,), n_segments=21)[0]  # one segment left over
    reasons = {}
    for protocol in ("condition_holdout", "unseen_fault", "specimen_holdout", "record_split"):
        table = make_splits(
            records, protocol_from(protocol, bearing_offered()), reserve=RESERVE, reasons=True
        )
        reasons[protocol] = table
    held = reasons["condition_holdout"]
    held = held[
        (held.holdout == "load=1") & held.record_id.str.endswith("-1") & (held.role == "test")
    ]
    assert set(held.reason) == {"held-out condition load=1"}
    unseen = reasons["unseen_fault"]
    assert set(unseen.reason[unseen.record_id == "ball-0.007-0"]) == {
        "class ball never measured in training: unseen"
    }
    cut = unseen[unseen.record_id == "normal-0"]
    assert set(cut.reason[cut.role == "calibration"]) == {
        "calibration block of the lone normal record (calibration.reserve)"
    }
    assert set(cut.reason[cut.role == "unused"]) == {
        "guard gap before a time block",
        "left over after the last time block",
    }
    blocks = cut.reason[cut.role.isin(["train", "test"])]
    assert blocks.str.startswith("time block normal-0@block").all()
    specimen = reasons["specimen_holdout"]
    tested = specimen[
        (specimen.holdout == "specimen_group=0.014")
        & (specimen.role == "test")
        & (specimen.record_id != "normal-0")
    ]
    assert set(tested.reason) == {"held-out specimen group 0.014"}
    split = reasons["record_split"]
    at100 = split[(split.measured_percent == 100) & (split.record_id == "ball-0.007-0")]
    assert at100.reason.str.match(
        r"(in the training share|kept back for testing) .* ball at "
        r"load=0"
    ).all()
    whole = make_splits(
        bearing()[0],
        protocol_from("record_split", bearing_offered()),
        reserve=RESERVE,
        reasons=True,
    )
    assert set(whole.reason[whole.role == "calibration"]) == {
        "calibration record of normal at load=0"
    }


# -- no function of the split code takes more than 10 parameters ----------------------------------
def test_no_split_function_takes_more_than_ten_parameters():
    files = [
        ROOT / "workflow/condmon/hybrid.py",
        *sorted((ROOT / "workflow/condmon/protocols").glob("*.py")),
    ]
    too_many = []
    for path in files:
        for node in ast.walk(ast.parse(Path(path).read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = node.args
                n = (
                    len(args.posonlyargs)
                    + len(args.args)
                    + len(args.kwonlyargs)
                    + (args.vararg is not None)
                    + (args.kwarg is not None)
                )
                if n > 10:
                    too_many.append(f"{Path(path).name}:{node.name} ({n})")
    assert not too_many


def test_the_schema_offers_exactly_the_registered_protocols():
    import yaml

    schema = yaml.safe_load((ROOT / "config/schema.yaml").read_text())
    protocols = schema["properties"]["hybrid"]["properties"]["protocols"]
    assert protocols["items"]["enum"] == list(PROTOCOLS)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_the_protocols_scheduled_first_are_those_with_the_most_fits(protocol):
    """`holds_out_each_group` (train.smk starts those protocols' jobs first) is true of the
    protocols that fit once per held-out group: on the bench layout (four loads, three fault
    sizes), more holdouts per share and repeat than any protocol without it."""
    records = bearing()[0]
    chosen = protocol_from(protocol, bearing_offered())
    table = make_splits(records, chosen, reserve=RESERVE)
    holdouts = table.groupby(["measured_percent", "repeat"])["holdout"].nunique().max()
    others = [
        make_splits(records, protocol_from(name, bearing_offered()), reserve=RESERVE)
        .groupby(["measured_percent", "repeat"])["holdout"]
        .nunique()
        .max()
        for name in PROTOCOLS
        if not REGISTRY[name].holds_out_each_group
    ]
    if REGISTRY[protocol].holds_out_each_group:
        assert holdouts > max(others)
    else:
        assert holdouts <= max(others)
