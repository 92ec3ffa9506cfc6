"""A view's region as a plan file records it (`plan_records.region_record`): one bit a face,
deflated, read back to the same faces or refused in one line."""

from __future__ import annotations

import base64
import zlib

import numpy as np
import pytest

from scanplan.core.plan_records import region_faces, region_record, validated_records


def test_a_region_reads_back_to_its_faces_and_stays_small():
    faces = np.r_[np.arange(1000, 40000), np.arange(70000, 70010)]
    record = region_record(faces, 100_003)
    assert record["faces"] == 100_003
    assert len(record["mask"]) < 1000  # a region in runs deflates to little
    assert np.array_equal(region_faces(record, 100_003, "p"), faces)
    views = [{"index": 0, "axis": [0.0, 0.0, 1.0], "first_swath": 0, "last_swath": 1}]
    read = validated_records({"views": [views[0] | {"region": record}]}, "p")
    assert read["views"][0]["region"] == record  # the file's record, as written


def mask_of(data: bytes) -> str:
    return base64.b64encode(zlib.compress(data)).decode()


@pytest.mark.parametrize(
    ("record", "fragment"),
    [
        (
            {"faces": 17, "mask": mask_of(b"\xff\xff\x80")},
            "of a part of 17 faces; this part has 16",
        ),
        ({"faces": 16, "mask": "not base64!"}, "is not 16 faces' bits"),
        ({"faces": 16, "mask": mask_of(b"\xff")}, "is not 16 faces' bits"),  # too short
        ({"faces": 16, "mask": mask_of(b"\xff" * 3)}, "is not 16 faces' bits"),  # too long
        ({"faces": 16, "mask": mask_of(b"\xff\xff")[:-8]}, "is not 16 faces' bits"),  # cut
        ({"faces": 16, "mask": mask_of(b"\x00\x00")}, "holds no face"),
    ],
)
def test_a_bad_region_is_refused_in_one_line(record, fragment):
    with pytest.raises(ValueError, match="^p: ") as err:
        region_faces(record, 16, "p")
    assert fragment in str(err.value) and "\n" not in str(err.value)


def test_the_file_reader_refuses_a_malformed_region_record():
    view = {"index": 0, "axis": [0.0, 0.0, 1.0], "first_swath": 0, "last_swath": 1}
    for region in ({"faces": 0, "mask": "AA=="}, {"faces": 4}, {"faces": 4, "mask": 3}):
        with pytest.raises(ValueError, match=r"views\.0\.region|views\[0\]\.region"):
            validated_records({"views": [view | {"region": region}]}, "p")


def test_the_file_reader_refuses_a_mask_that_does_not_decode():
    view = {"index": 0, "axis": [0.0, 0.0, 1.0], "first_swath": 0, "last_swath": 1}
    region = {"faces": 16, "mask": mask_of(b"\xff")}  # 8 faces' bits for 16
    with pytest.raises(ValueError, match="is not 16 faces' bits") as err:
        validated_records({"views": [view | {"region": region}]}, "p")
    assert "\n" not in str(err.value)
