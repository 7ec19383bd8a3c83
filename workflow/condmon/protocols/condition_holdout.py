"""condition_holdout: each condition in turn is held out whole as the test set; the training
share is drawn per stratum from the other conditions' records, and the records not drawn are
"unused" (neither trained on nor tested; every record still has a row). With `condition_split`
({train: [...], test: [...]}, a benchmark's fixed split of the conditions) there is one
holdout: the test conditions test, the share trains from the train conditions, other
conditions are unused; a listed condition the measured records lack is an error naming it.

The held-out conditions supply the test set, so no record of the other conditions stays back
for testing (at 100 % all of them train), except where they have no healthy record: then
max(1, min_test_records) healthy records per other stratum test, so false alarms are measured
(at another condition: the report's protocol label says so)."""

from __future__ import annotations

from condmon.hybrid import SplitError, n_train_records
from condmon.labels import format_speed, holdout_label
from condmon.protocols.base import Protocol


class ConditionHoldout(Protocol):
    name = "condition_holdout"
    holds_out_each_group = True

    def __init__(
        self,
        measured_percent,
        repeats,
        seed,
        min_test_records=1,
        condition="speed_rpm",
        healthy_state=None,
        condition_split: dict | None = None,
    ):
        super().__init__(
            measured_percent, repeats, seed, min_test_records, condition, healthy_state
        )
        self.condition_split = condition_split or None
        self.conditions: list[float] = []

    def check(self, units):
        self.conditions = sorted(units["condition"].unique())
        if self.condition_split:
            self.sides(self.conditions)
        if len(self.conditions) < 2:
            raise SplitError(
                f"condition_holdout needs at least two values of {self.condition}; "
                f"the measured records have only {self.condition} "
                f"{[format_speed(c) for c in self.conditions]}"
            )

    def sides(self, conditions) -> tuple[list, list]:
        """(train, test) condition values of hybrid.condition_split, each one measured, or an
        error naming the missing ones (a benchmark's split needs its loads in the folder)."""
        split, condition = self.condition_split, self.condition
        train, test = ([float(v) for v in split.get(side) or []] for side in ("train", "test"))
        if not train or not test:
            raise SplitError(
                f"hybrid.condition_split needs train and test {condition} values, got {split}"
            )
        both = sorted(set(train) & set(test))
        if both:
            raise SplitError(
                f"hybrid.condition_split: {condition} "
                f"{[format_speed(v) for v in both]} is on both sides"
            )
        missing = sorted(set(train + test) - set(conditions))
        if missing:
            raise SplitError(
                f"hybrid.condition_split needs measured records at {condition} "
                f"{[format_speed(v) for v in missing]}, which the measured data lack (they have "
                f"{condition} {[format_speed(v) for v in conditions]}): point measured_dir at a "
                "folder with those records, or change the split"
            )
        return train, test

    def assign(self, orders, percent):
        if self.condition_split:
            train_conditions, test_conditions = self.sides(self.conditions)
            held_out_sets = [test_conditions]
        else:
            train_conditions, held_out_sets = None, [[value] for value in self.conditions]
        healthy_there = {value for health, value in orders if health == self.healthy_state}
        for held_out in held_out_sets:
            keep = (
                max(1, self.min_test_records)
                if self.healthy_state is not None and not healthy_there & set(held_out)
                else 0
            )
            yield (
                self.holdout(held_out),
                self.rows(orders, percent, held_out, keep, train_conditions),
            )

    def holdout(self, held_out) -> str:
        """ "speed_rpm=775", or "load=2+3" for several held-out conditions."""
        return "+".join(
            holdout_label(value, self.condition) if i == 0 else format_speed(value)
            for i, value in enumerate(sorted(held_out))
        )

    def rows(self, orders, percent, held_out, keep, train_conditions):
        rows = []
        for (health, value), ids in orders.items():
            where = holdout_label(value, self.condition)
            if value in held_out:
                rows += [(rid, "test", f"held-out condition {where}") for rid in ids]
                continue
            if train_conditions is not None and value not in train_conditions:
                rows += [
                    (rid, "unused", f"condition {where} on neither side of condition_split")
                    for rid in ids
                ]
                continue
            keep_here = keep if health == self.healthy_state else 0
            n_train = n_train_records(len(ids), percent, keep_here)
            drawn = f"{n_train} of {len(ids)} records of {self.stratum(health, value)} train"
            for i, rid in enumerate(ids):
                if i < n_train:
                    rows.append((rid, "train", f"in the training share ({drawn})"))
                elif i >= len(ids) - keep_here:
                    rows.append(
                        (
                            rid,
                            "test",
                            f"kept back for testing: the held-out condition has no {health} record",
                        )
                    )
                else:
                    rows.append((rid, "unused", f"not drawn for training ({drawn})"))
        return rows
