"""nav2 map_server file io: pixel rules, round trips, atomic writes, errors."""

from __future__ import annotations

import math
import os
import sys
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from eddiebot.maps import (
    LegacyMapWarning,
    MapFormatError,
    MapWriteError,
    OccupancyMap,
    image_to_map,
    is_inside,
    load_map,
    map_from_msg,
    map_to_image,
    map_to_msg,
    map_to_world,
    save_map,
    world_to_map,
)


def _sample_map() -> OccupancyMap:
    data = np.full((4, 5), -1, dtype=np.int8)
    data[0, :] = 0
    data[1, 1] = 100
    data[2, 3] = 70
    data[3, 4] = 20
    return OccupancyMap(data=data, resolution=0.05, origin=(-1.0, 2.5, 0.0))


def test_trinary_pixels_match_map_saver() -> None:
    img = map_to_image(_sample_map())
    # image row 0 is the top (highest y) = map row 3
    assert img.shape == (4, 5)
    assert img[3, 0] == 254  # free
    assert img[2, 1] == 0  # occupied
    assert img[1, 3] == 0  # 70 >= 65
    assert img[0, 4] == 254  # 20 <= rint(0.196 * 100)
    assert img[0, 0] == 205  # unknown


def test_trinary_load_thresholds() -> None:
    # occ = 1 - p/255: 0 -> 1.0 occupied, 254 -> 0.004 free, 128 -> 0.498 unknown, 90 -> 0.647
    # unknown, 205 -> 0.19608: unknown with the default free_thresh 0.196 ...
    img = np.array([[0, 254, 205, 128, 90]], dtype=np.uint8)
    grid = image_to_map(img, resolution=0.1)
    assert grid.data.tolist() == [[100, 0, -1, -1, -1]]
    # ... and free with 0.25, as map_server reads it (nav2's old default).
    old = image_to_map(img, resolution=0.1, free_thresh=0.25)
    assert old.data.tolist() == [[100, 0, 0, -1, -1]]
    neg = image_to_map(img, resolution=0.1, negate=True, free_thresh=0.25)
    assert neg.data.tolist() == [[0, 100, 100, -1, -1]]


def test_scale_and_raw_modes() -> None:
    img = np.array([[0, 255, 150, 50]], dtype=np.uint8)
    scale = image_to_map(img, resolution=0.1, mode="scale")
    occ = 1 - 150 / 255
    assert scale.data[0, 2] == round((occ - 0.196) / (0.65 - 0.196) * 100)
    assert scale.data.tolist()[0][:2] == [100, 0]
    raw = image_to_map(img, resolution=0.1, mode="raw")
    assert raw.data.tolist() == [[0, -1, -1, 50]]


@pytest.mark.parametrize("mode", ["trinary", "raw"])
@pytest.mark.parametrize("negate", [False, True])
def test_save_load_round_trip(tmp_path: Path, mode: str, negate: bool) -> None:
    grid = _sample_map()
    yaml_path = save_map(grid, tmp_path / "office", mode=mode, negate=negate)
    assert yaml_path == tmp_path / "office.yaml"
    assert (tmp_path / "office.pgm").read_bytes().startswith(b"P5")
    loaded = load_map(yaml_path)
    assert loaded.resolution == grid.resolution
    assert loaded.origin == grid.origin
    if mode == "raw":
        assert np.array_equal(loaded.data, grid.data)
    else:
        # Unknown is written as grey 205, which free_thresh 0.196 reads back as unknown.
        known_free = (grid.data >= 0) & (grid.data <= 20)
        expected = np.where(grid.data >= 65, 100, np.where(known_free, 0, -1))
        assert np.array_equal(loaded.data, expected)
    assert not list(tmp_path.glob("*.tmp"))


def test_scale_png_keeps_unknown_as_transparency(tmp_path: Path) -> None:
    grid = _sample_map()
    save_map(grid, tmp_path / "m", mode="scale", image_format="png")
    loaded = load_map(tmp_path / "m.yaml")
    assert np.array_equal(loaded.data < 0, grid.data < 0)
    assert loaded.data[1, 1] == 100


def test_yaml_written_like_map_saver(tmp_path: Path) -> None:
    save_map(_sample_map(), tmp_path / "m")
    text = (tmp_path / "m.yaml").read_text()
    assert "image: m.pgm" in text
    assert "mode: trinary" in text
    assert "occupied_thresh: 0.65" in text
    assert "free_thresh: 0.196" in text
    assert "origin: [-1.0, 2.5, 0.0]" in text


@pytest.mark.skipif(sys.platform == "win32" or os.geteuid() == 0, reason="needs permissions")
def test_atomic_write_failure_keeps_previous_map(tmp_path: Path) -> None:
    grid = _sample_map()
    save_map(grid, tmp_path / "m")
    before = ((tmp_path / "m.pgm").read_bytes(), (tmp_path / "m.yaml").read_bytes())
    changed = OccupancyMap(np.zeros((4, 5), np.int8), 0.1)
    tmp_path.chmod(0o500)
    try:
        with pytest.raises(MapWriteError, match=r"m\.pgm"):
            save_map(changed, tmp_path / "m")
    finally:
        tmp_path.chmod(0o700)
    assert ((tmp_path / "m.pgm").read_bytes(), (tmp_path / "m.yaml").read_bytes()) == before
    assert load_map(tmp_path / "m.yaml") == load_map(tmp_path / "m.yaml")


def test_failed_write_midway_keeps_previous_map(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    grid = _sample_map()
    save_map(grid, tmp_path / "m")
    before = ((tmp_path / "m.pgm").read_bytes(), (tmp_path / "m.yaml").read_bytes())

    def disk_full(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(MapWriteError, match="No space left"):
        save_map(OccupancyMap(np.zeros((4, 5), np.int8), 0.1), tmp_path / "m")
    monkeypatch.undo()
    assert ((tmp_path / "m.pgm").read_bytes(), (tmp_path / "m.yaml").read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pgm", "m.yaml"]


def test_unwritable_path_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(MapWriteError, match="file"):
        save_map(_sample_map(), tmp_path / "file" / "m")


def test_missing_folder_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(MapWriteError, match="does not exist"):
        save_map(_sample_map(), tmp_path / "nowhere" / "m")


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("image: m.pgm\norigin: [0, 0, 0]\n", "resolution"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", "resolution"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n", "origin"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n", "mode"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 3\n", "negate"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.9\n", "free_thresh"),
        ("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", "image"),
        ("resolution: 0.05\norigin: [0, 0, 0]\n", "image"),
    ],
)
def test_yaml_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(MapFormatError) as info:
        load_map(path)
    assert str(path) in str(info.value)
    assert f"'{key}'" in str(info.value)


def test_undecodable_image(tmp_path: Path) -> None:
    (tmp_path / "m.pgm").write_bytes(b"not an image")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapFormatError, match=r"m\.pgm"):
        load_map(tmp_path / "m.yaml")


def test_coordinates_and_msg_round_trip() -> None:
    grid = OccupancyMap(np.zeros((10, 20), np.int8), 0.5, origin=(1.0, -2.0, 0.0))
    cells = world_to_map(grid, [[1.26, -1.9], [0.9, 0.0]])
    assert cells.tolist() == [[0, 0], [-1, 4]]
    assert is_inside(grid, cells).tolist() == [True, False]
    assert np.allclose(map_to_world(grid, [3, 2]), [1.0 + 1.75, -2.0 + 1.25])
    rotated = OccupancyMap(np.zeros((10, 20), np.int8), 0.5, origin=(1.0, -2.0, math.pi / 2))
    assert world_to_map(rotated, map_to_world(rotated, [[5, 7]])).tolist() == [[5, 7]]
    msg = map_to_msg(rotated, stamp_ns=3_500_000_000)
    assert msg.info.width == 20
    assert msg.info.height == 10
    assert msg.header.stamp.sec == 3
    assert msg.header.frame_id == "map"
    back = map_from_msg(msg)
    assert back.data.shape == (10, 20)
    assert back.origin == pytest.approx(rotated.origin)


def test_map_is_immutable() -> None:
    grid = _sample_map()
    with pytest.raises(ValueError, match="read-only"):
        grid.data[0, 0] = 5


# -- unknown stays unknown ----------------------------------------------------------------
def _explored_map() -> OccupancyMap:
    """60 x 80 cells: an explored room (free, walls) inside unexplored space."""
    data = np.full((60, 80), -1, dtype=np.int8)
    data[10:50, 10:70] = 0
    data[10, 10:70] = data[49, 10:70] = 100
    data[10:50, 10] = data[10:50, 69] = 100
    return OccupancyMap(data=data, resolution=0.05, origin=(-2.0, -1.5, 0.0))


def _write_map(folder: Path, name: str, image: np.ndarray, yaml_text: str) -> Path:
    cv2.imwrite(str(folder / f"{name}.pgm"), image)
    path = folder / f"{name}.yaml"
    path.write_text(f"image: {name}.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n" + yaml_text)
    return path


def test_save_load_round_trip_keeps_unknown_cells(tmp_path: Path) -> None:
    grid = _explored_map()
    unknown = int((grid.data == -1).sum())
    assert unknown == 60 * 80 - 40 * 60  # 2400
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a file this version writes loads without a warning
        loaded = load_map(save_map(grid, tmp_path / "room"))
    assert int((loaded.data == -1).sum()) == 2400
    assert int((loaded.data == 100).sum()) == int((grid.data == 100).sum()) == 196
    assert int((loaded.data == 0).sum()) == 40 * 60 - 196


def test_thresholds_from_a_float32_request_are_written_as_given(tmp_path: Path) -> None:
    # SaveMap carries float32: 0.196 arrives as 0.19599999487400055
    free, occupied = float(np.float32(0.196)), float(np.float32(0.65))
    save_map(_explored_map(), tmp_path / "m", free_thresh=free, occupied_thresh=occupied)
    text = (tmp_path / "m.yaml").read_text()
    assert "free_thresh: 0.196\n" in text
    assert "occupied_thresh: 0.65\n" in text


@pytest.mark.parametrize("occupied", ["0.65", "0.6499999761581421"])
def test_legacy_file_loads_with_unknown_and_one_warning(tmp_path: Path, occupied: str) -> None:
    # What eddiebot wrote before: greys 0 / 205 / 254 with free_thresh 0.25 (occupied 0.65,
    # or its float32 form when saved through the SaveMap service).
    image = map_to_image(_explored_map(), free_thresh=0.25)
    path = _write_map(tmp_path, "old", image,
                      f"mode: trinary\nnegate: 0\noccupied_thresh: {occupied}\nfree_thresh: 0.25\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = load_map(path)
    assert int((loaded.data == -1).sum()) == 2400
    assert int((loaded.data == 0).sum()) == 40 * 60 - 196
    assert len(caught) == 1
    assert issubclass(caught[0].category, LegacyMapWarning)
    message = str(caught[0].message)
    assert str(path) in message
    assert "save" in message.lower()


def test_legacy_negated_file_loads_with_unknown(tmp_path: Path) -> None:
    image = map_to_image(_explored_map(), free_thresh=0.25, negate=True)  # greys 255 / 50 / 1
    path = _write_map(tmp_path, "neg", image,
                      "mode: trinary\nnegate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    with pytest.warns(LegacyMapWarning):
        loaded = load_map(path)
    assert int((loaded.data == -1).sum()) == 2400


def test_third_party_file_without_205_loads_as_map_server(tmp_path: Path) -> None:
    # A hand-made map with free_thresh 0.25 and greys other than 205: map_server's rules,
    # occ = (255 - p) / 255; occ > 0.65 -> 100, occ < 0.25 -> 0, else -1.
    row = [0, 50, 89, 90, 191, 192, 200, 230, 254, 255]
    image = np.array([row, row[::-1]], dtype=np.uint8)
    path = _write_map(tmp_path, "third", image,
                      "mode: trinary\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_map(path)
    # occ: 1.0, 0.804, 0.651, 0.647, 0.251, 0.247, 0.216, 0.098, 0.004, 0.0
    expected = [100, 100, 100, -1, -1, 0, 0, 0, 0, 0]
    assert loaded.data[1].tolist() == expected  # image row 0 is the top row
    assert loaded.data[0].tolist() == expected[::-1]


def test_third_party_file_with_205_among_other_greys_loads_as_map_server(
    tmp_path: Path,
) -> None:
    image = np.array([[0, 205, 254, 128]], dtype=np.uint8)
    path = _write_map(tmp_path, "mixed", image,
                      "mode: trinary\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_map(path)
    assert loaded.data.tolist() == [[100, 0, 0, -1]]  # 205 -> occ 0.196 < 0.25: free
