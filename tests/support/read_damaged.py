"""Child of helpers.read_each_bounded: `read_damaged.py JSON_LOCATIONS [ASSIGNMENT ...]` opens
each location with its dataset plugin (the assignments applied as `--set` applies them) and
reads all it holds (IMU and ground truth are read on opening), printing `start<TAB>location`
before and `done<TAB>ok` or `done<TAB>its error` after each; a user error must be one line.
Every read gets an event cache of its own."""

import json
import os
import sys
import tempfile

from eas_vo.config import resolve
from eas_vo.errors import EasVoError
from eas_vo.registry import open_dataset


def read_all(location: str, assignments: list[str]) -> None:
    config = resolve(None, {"dataset": location}, assignments)
    dataset = open_dataset(config.run.dataset, config.dataset)
    dataset.events()
    for k in range(len(dataset.frame_times())):
        dataset.load_frame(k)


def main() -> None:
    locations, assignments = json.loads(sys.argv[1]), sys.argv[2:]
    for location in locations:
        print(f"start\t{location}", flush=True)
        with tempfile.TemporaryDirectory() as cache:
            os.environ["EAS_VO_CACHE_DIR"] = cache
            try:
                read_all(location, assignments)
                outcome = "ok"
            except EasVoError as exc:
                outcome = str(exc)
                if "\n" in outcome:
                    outcome = f"NOT ONE LINE: {outcome!r}"
        print(f"done\t{outcome}", flush=True)


if __name__ == "__main__":
    main()
