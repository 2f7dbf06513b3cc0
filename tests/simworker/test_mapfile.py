"""The map_server codec: loading, saving, modes, coordinates and bad files."""

import pytest

from fleetcore.mapfile import FREE, OCCUPIED, UNKNOWN, MapFormatError, OccupancyGrid, load_map, save_map

YAML = "image: m.pgm\nresolution: 0.5\norigin: [-1.0, -2.0, 0.0]\nnegate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{mode}"


def write_map(tmp_path, pixels, width, height, negate=0, mode=""):
    """Write a P5 PGM (top row first) and its YAML; return the YAML path."""
    (tmp_path / "m.pgm").write_bytes(
        f"P5\n# made by a test\n{width} {height}\n255\n".encode() + bytes(pixels)
    )
    path = tmp_path / "m.yaml"
    path.write_text(YAML.format(negate=negate, mode=mode))
    return path


def test_trinary_map_flips_rows_so_cell_zero_is_bottom_left(tmp_path):
    grid = load_map(write_map(tmp_path, [0, 254, 205, 254, 254, 254], 3, 2))
    assert (grid.width, grid.height, grid.resolution) == (3, 2, 0.5)
    assert grid.data == [FREE, FREE, FREE, OCCUPIED, FREE, UNKNOWN]


def test_negate_swaps_black_and_white(tmp_path):
    grid = load_map(write_map(tmp_path, [0, 254], 2, 1, negate=1))
    assert grid.data == [FREE, OCCUPIED]


def test_scale_mode_keeps_intermediate_occupancy(tmp_path):
    grid = load_map(write_map(tmp_path, [128], 1, 1, mode="mode: scale\n"))
    assert 1 <= grid.data[0] <= 99


def test_raw_mode_keeps_pixel_values(tmp_path):
    grid = load_map(write_map(tmp_path, [7, 100], 2, 1, mode="mode: raw\n"))
    assert grid.data == [7, 100]


def test_world_and_cell_coordinates_use_the_origin(tmp_path):
    grid = load_map(write_map(tmp_path, [254, 0, 254, 254], 2, 2))
    assert grid.world_to_cell(-1.0, -2.0) == (0, 0)
    assert grid.world_to_cell(-0.3, -1.3) == (1, 1)
    assert grid.cell_to_world(1, 1) == (-0.25, -1.25)
    assert grid.is_free(-0.75, -1.75)
    assert not grid.is_free(-0.25, -1.25)  # top-right pixel is black
    assert not grid.is_free(50.0, 50.0)  # off the map counts as unknown


def test_save_then_load_round_trips_like_map_saver(tmp_path):
    grid = OccupancyGrid(0.05, 3, 2, (1.0, 2.0, 0.0), [FREE, OCCUPIED, UNKNOWN, 10, 80, 50])
    save_map(grid, tmp_path / "saved.yaml")
    assert (
        (tmp_path / "saved.pgm")
        .read_bytes()
        .startswith(b"P5\n# CREATOR: map_saver.cpp 0.050 m/pix\n3 2\n255\n")
    )
    again = load_map(tmp_path / "saved.yaml")
    assert again.data == [FREE, OCCUPIED, UNKNOWN, FREE, OCCUPIED, UNKNOWN]
    assert again.origin == (1.0, 2.0, 0.0)


def test_to_msg_encodes_ros1_and_ros2_headers(tmp_path):
    grid = OccupancyGrid(0.5, 1, 1, (0.0, 0.0, 0.0), [FREE])
    ros1, ros2 = grid.to_msg(1, stamp=12.5), grid.to_msg(2, stamp=12.5)
    assert ros1["header"]["stamp"] == {"secs": 12, "nsecs": 500000000} and ros1["header"]["seq"] == 0
    assert ros2["header"]["stamp"] == {"sec": 12, "nanosec": 500000000} and "seq" not in ros2["header"]
    assert ros1["info"]["origin"]["orientation"]["w"] == 1.0 and ros1["data"] == [0]


@pytest.mark.parametrize(
    ("yaml_text", "problem"),
    [
        ("resolution: 0.05\n", "missing key"),
        (
            "image: m.pgm\nresolution: x\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "resolution",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "origin",
        ),
        (
            "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\nmode: odd\n",
            "mode",
        ),
        ("image: [unclosed\n", "not valid YAML"),
        (
            "image: nope.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "cannot read image",
        ),
    ],
)
def test_bad_map_files_raise_one_line_errors_naming_the_file(tmp_path, yaml_text, problem):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml_text)
    with pytest.raises(MapFormatError) as err:
        load_map(path)
    assert problem in str(err.value) and str(path.name) in str(err.value) and "\n" not in str(err.value)


def test_a_non_pgm_image_is_refused(tmp_path):
    write_map(tmp_path, [0], 1, 1)
    (tmp_path / "m.pgm").write_bytes(b"\x89PNG....")
    with pytest.raises(MapFormatError, match="not a PGM"):
        load_map(tmp_path / "m.yaml")


def test_a_truncated_pgm_is_refused(tmp_path):
    path = write_map(tmp_path, [0, 0], 2, 2)
    with pytest.raises(MapFormatError, match="truncated"):
        load_map(path)
