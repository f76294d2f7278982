"""The 3-D viewer: beam geometry, time-of-flight ellipsoids, path meshes, results parsing, camera
presets, off-screen rendering and the ``acoustisim view`` command."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.special import j1

from acoustisim.errors import InputError
from acoustisim.propagation.paths import PathKind, Paths, empty_paths_array
from acoustisim.scene import Scene, Tank
from acoustisim.sonar import SonarHead
from acoustisim.viz.actors import (
    EstimateMarker,
    TruthMarker,
    choose_echo,
    estimate_layers,
    path_layers,
    path_opacity,
    path_polylines,
    tof_ellipsoid,
)
from acoustisim.viz.beam import piston_beam_angles
from acoustisim.viz.cameras import camera_preset
from acoustisim.viz.results_file import load_results, parse_results

C_WATER = 1482.38  # m/s, fresh water at 20 C (physics.md section 1)


# ------------------------------------------------------------------------------------------ beam
def test_beam_angles_match_the_piston_formula_and_the_reference_values():
    angles = piston_beam_angles(0.0095, 500e3, C_WATER)
    ka = angles.ka
    # physics.md section 2: ka = 20.1, -3 dB at 4.60 deg, first null 11.0 deg (printed to 3
    # significant figures, hence the 0.01 / 0.05 deg tolerances).
    assert ka == pytest.approx(20.13, abs=0.01)
    assert angles.half_power_deg == pytest.approx(4.60, abs=0.01)
    assert angles.first_null_deg == pytest.approx(11.0, abs=0.05)
    # Independent check: the directivity 2 J1(x)/x evaluated at the returned angles.
    x_half = ka * math.sin(math.radians(angles.half_power_deg))
    assert 20 * math.log10(2 * j1(x_half) / x_half) == pytest.approx(-3.0, abs=1e-6)
    x_null = ka * math.sin(math.radians(angles.first_null_deg))
    assert abs(2 * j1(x_null) / x_null) < 1e-9
    # The side lobe's peak is a local maximum of |D| between the first and second nulls, at
    # the classic -17.6 dB.
    theta = np.radians(np.linspace(angles.first_null_deg + 0.1, 20.0, 4001))
    x = ka * np.sin(theta)
    level = 20 * np.log10(np.abs(2 * j1(x) / x))
    assert np.degrees(theta[np.argmax(level)]) == pytest.approx(angles.side_lobe_deg, abs=0.01)
    assert angles.side_lobe_db == pytest.approx(level.max(), abs=1e-3)
    assert angles.side_lobe_db == pytest.approx(-17.57, abs=0.01)


def test_beam_angles_of_a_small_piston_have_no_null():
    angles = piston_beam_angles(0.0005, 500e3, C_WATER)  # ka = 1.06 < 3.83: D never reaches zero
    assert angles.first_null_deg is None and angles.side_lobe_deg is None
    with pytest.raises(ValueError, match="radius_m"):
        piston_beam_angles(-1.0, 500e3, C_WATER)


# ----------------------------------------------------------------------------------- ellipsoids
@pytest.mark.parametrize("receiver", [(0.065, 0.0, 0.0), (0.0, 0.0, 0.0), (0.3, -0.2, 0.1)])
def test_tof_ellipsoid_is_the_locus_of_constant_path_length(receiver):
    tx = np.array([1.0, 1.5, 0.5])
    rx = tx + np.array(receiver)
    length = 3.7
    mesh = tof_ellipsoid(tx, rx, length)
    p = np.asarray(mesh.points)
    total = np.linalg.norm(p - tx, axis=1) + np.linalg.norm(p - rx, axis=1)
    # Exact construction: only float rounding (1e-12 relative) separates it from L.
    np.testing.assert_allclose(total, length, rtol=1e-12)
    # It reaches the far end of the focal axis (the extreme vertices are on the sphere's poles
    # or its equator, so the extent along any axis is that of the ellipsoid to 1 %).
    assert np.max(np.linalg.norm(p - 0.5 * (tx + rx), axis=1)) == pytest.approx(length / 2, rel=1e-2)
    with pytest.raises(ValueError, match="focal"):
        tof_ellipsoid(tx, tx + np.array([1.0, 0.0, 0.0]), 0.5)


# ---------------------------------------------------------------------------------------- paths
def _hand_paths(sonar: SonarHead) -> Paths:
    """Rows of known geometry: a direct path, a first- and a second-order specular path on the
    three channels, and two edge elements of one diffraction."""
    rows = empty_paths_array(8)
    tx = sonar.transmitter_position
    spec = [  # (kind, order, points, amplitude, channel, path_id)
        (PathKind.DIRECT, 0, [], 0.5, 0, 0),
        (PathKind.SPECULAR, 1, [[3.0, 1.5, 0.5]], 1e-2, 0, 1),
        (PathKind.SPECULAR, 1, [[3.0, 1.5, 0.5]], 1e-2, 1, 1),
        (PathKind.SPECULAR, 1, [[3.0, 1.5, 0.5]], 1e-2, 2, 1),
        (PathKind.SPECULAR, 2, [[5.0, 0.0, 0.5], [9.0, 1.5, 0.5]], 1e-3, 1, 2),
        (PathKind.EDGE, 1, [[2.5, 1.5, 0.50]], 1e-4, 1, 3),
        (PathKind.EDGE, 1, [[2.5, 1.5, 0.51]], 1e-4, 1, 3),
        (PathKind.DIFFUSE, 1, [[4.0, 2.0, 0.0]], 1e-6, 1, 4),
    ]
    for i, (kind, order, points, amp, channel, path_id) in enumerate(spec):
        rows[i]["kind"], rows[i]["order"], rows[i]["amplitude"] = kind, order, amp
        rows[i]["channel"], rows[i]["path_id"] = channel, path_id
        rows[i]["geometric_gain"] = amp
        rx = sonar.receiver_positions[channel]
        chain = np.vstack([tx, *points, rx]) if points else np.vstack([tx, rx])
        length = np.sum(np.linalg.norm(np.diff(chain, axis=0), axis=1))
        rows[i]["path_length_m"] = length
        rows[i]["delay_s"] = length / C_WATER
        for k, p in enumerate(points):
            rows[i]["points_m"][k] = p
            rows[i]["object_ids"][k] = 7 if kind == PathKind.EDGE else 6 + k  # the edge is on post-2
    return Paths(rows, ("wall-x0", "wall-x1", "wall-y0", "wall-y1", "floor", "surface", "post-1", "post-2"),
                 500e3, C_WATER)


def test_path_polylines_join_transmitter_points_and_receiver():
    sonar = SonarHead()
    paths = _hand_paths(sonar)
    points, segments, segment_row = path_polylines(paths, sonar)
    # Each row with k interaction points is k + 1 segments.
    expected = np.array([1, 2, 2, 2, 3, 2, 2, 2])
    np.testing.assert_array_equal(np.bincount(segment_row, minlength=8), expected)
    # The second-order path: tx -> (5, 0) -> (9, 1.5) -> centre receiver.
    chain = points[segments[segment_row == 4]]
    np.testing.assert_allclose(chain[0, 0], sonar.transmitter_position)
    np.testing.assert_allclose(chain[1, 0], [5.0, 0.0, 0.5])
    np.testing.assert_allclose(chain[2, 1], sonar.receiver_positions[1])


def test_path_layers_one_mesh_per_kind_with_fading_opacity():
    sonar = SonarHead()
    paths = _hand_paths(sonar)
    layers = {layer.name: layer for layer in path_layers(paths, sonar, edge_elements=True, dynamic_range_db=40.0)}
    assert set(layers) == {"paths-direct", "paths-specular", "paths-edge", "paths-diffuse"}
    specular = layers["paths-specular"]
    assert specular.mesh.n_cells == 3 * 2 + 3  # three first-order rows, one second-order row
    alpha = np.asarray(specular.mesh.cell_data["rgba"])[:, 3]
    # The reference is the strongest echo (1e-2), not the direct coupling (0.5): first-order
    # rows opaque, the second-order row 20 dB down at half the 40 dB range.
    assert alpha.max() == 255
    expected_half = round((0.04 + 0.96 * 0.5) * 255)
    assert sorted(set(alpha.tolist())) == [expected_half, 255]
    # Edge elements collapse to one arrival by default.
    collapsed = {layer.name: layer for layer in path_layers(paths, sonar)}
    assert collapsed["paths-edge"].mesh.n_cells == 2
    assert layers["paths-edge"].mesh.n_cells == 4
    # max_paths keeps the strongest rows.
    strongest = path_layers(paths, sonar, max_paths=1)
    assert [layer.name for layer in strongest] == ["paths-direct"]


def test_path_opacity_is_monotonic_and_bounded():
    amp = np.array([0.0, 1e-6, 1e-3, 1e-2, 1e-1, 1.0, 3.0])
    alpha = path_opacity(amp, 1.0, 40.0, 0.05)
    assert np.all(np.diff(alpha) >= 0)
    assert alpha[0] == pytest.approx(0.05) and alpha[-1] == pytest.approx(1.0)
    assert alpha[3] == pytest.approx(0.05)  # 1e-2 is -40 dB: the bottom of the range
    assert alpha[4] == pytest.approx(0.05 + 0.95 * 0.5)  # -20 dB: half way


def test_choose_echo_finds_the_same_arrival_on_every_channel():
    sonar = SonarHead()
    paths = _hand_paths(sonar)
    first = choose_echo(paths, 0)  # by delay: the edge at 1.5 m comes before the post at 2 m
    assert first.label.startswith("edge")
    assert np.isnan(first.path_length_m[0]) and np.isnan(first.path_length_m[2])
    second = choose_echo(paths, 1)
    assert second.label == "specular: post-1"
    # Path lengths per channel equal tx -> point -> receiver (the row's own geometry).
    point = np.array([3.0, 1.5, 0.5])
    expected = np.linalg.norm(point - sonar.transmitter_position) + np.linalg.norm(
        sonar.receiver_positions - point, axis=1)
    np.testing.assert_allclose(second.path_length_m, expected, rtol=1e-12)
    with pytest.raises(IndexError, match="echo 9"):
        choose_echo(paths, 9)
    # By surface name: the first single-bounce echo off it.
    by_name = choose_echo(paths, "post-1")
    assert by_name.index == 1 and by_name.label == "specular: post-1"
    with pytest.raises(IndexError, match="no single-bounce echo off 'floor'"):
        choose_echo(paths, "floor")
    with pytest.raises(IndexError, match="no surface"):
        choose_echo(paths, "nothing")


# -------------------------------------------------------------------------------------- results
def test_results_in_head_frame_are_placed_with_the_pose():
    sonar = SonarHead(position_m=(1.0, 1.5, 0.5), yaw_deg=90.0)  # boresight along tank +y
    data = {"pings": [{"ping": 0, "targets": [
        {"range_m": 2.0, "bearing_deg": 30.0, "range_std_m": 0.001, "bearing_std_deg": 0.5, "cls": "point"},
        {"position_head_m": [0.1, 1.0], "covariance": [[1e-6, 0.0], [0.0, 4e-6]]},
        {"position_tank_m": [3.0, 1.0, 0.5], "std_m": [0.01, 0.02, 0.03], "class": "plane"},
    ]}]}
    markers = parse_results(data, sonar)
    # Head x (toward the right receiver) is tank +x when the boresight is +y (yaw 90 deg).
    np.testing.assert_allclose(markers[0].position_m, [1.0 + 2.0 * math.sin(math.radians(30)),
                                                       1.5 + 2.0 * math.cos(math.radians(30)), 0.5], atol=1e-12)
    assert markers[0].cls == "point"
    # Range/bearing covariance: the range variance lies along the line of sight, the bearing
    # variance (r sigma_theta)^2 across it.
    cov = markers[0].covariance_m2
    los = (markers[0].position_m - np.array(sonar.position_m)) / 2.0
    assert los @ cov @ los == pytest.approx(1e-6, rel=1e-9)
    across = np.cross([0, 0, 1], los)
    assert across @ cov @ across == pytest.approx((2.0 * math.radians(0.5)) ** 2, rel=1e-9)
    np.testing.assert_allclose(markers[1].position_m, [1.0 + 0.1, 1.5 + 1.0, 0.5], atol=1e-12)
    # Head y variance (4e-6) is tank y variance after the rotation.
    assert markers[1].covariance_m2[1, 1] == pytest.approx(4e-6) and markers[1].covariance_m2[0, 0] == pytest.approx(1e-6)
    np.testing.assert_allclose(np.diag(markers[2].covariance_m2), [1e-4, 4e-4, 9e-4])
    assert markers[2].cls == "plane"


def test_results_as_binsonar_writes_them():
    """The layout of ``binsonar localize --json``: nulls for non-finite values, tank positions
    when the recording has poses, per-axis standard deviations."""
    sonar = SonarHead()
    data = {"source": "p.h5", "pings": [{"ping": 0, "pose": [1.0, 1.5, 0.5, 0.0, 0.0, 0.0], "targets": [
        {"class": "cylinder", "status": "ok", "range_m": 2.0, "bearing_deg": 0.0, "position_head_m": [0.0, 2.0, 0.0],
         "position_head_std_m": [0.002, 0.001, None], "position_tank_m": [3.0, 1.5, 0.5],
         "position_tank_std_m": [0.001, 0.002, 0.0]},
        {"class": "unknown", "status": "failed", "range_m": None, "bearing_deg": None, "position_head_m": None,
         "position_tank_m": None},
        {"class": "point", "status": "ok", "range_m": 1.0, "bearing_deg": 90.0, "position_tank_m": [None, 1.0, 0.5]},
    ]}], "fused": []}
    markers = parse_results(data, sonar)
    assert len(markers) == 2  # the failed fit has no position and is left out
    np.testing.assert_allclose(markers[0].position_m, [3.0, 1.5, 0.5])
    np.testing.assert_allclose(np.diag(markers[0].covariance_m2), [1e-6, 4e-6, 0.0])
    assert markers[0].cls == "cylinder"
    # A tank position with a null falls back to range and bearing (90 deg: toward the right
    # receiver, tank -y at yaw 0).
    np.testing.assert_allclose(markers[1].position_m, [1.0, 0.5, 0.5], atol=1e-12)


@pytest.mark.parametrize(
    "data, message",
    [
        ({"targets": [{"class": "point", "radius_m": 0.1}]}, r"targets\[0\]: no position"),
        ({"targets": [{"position_tank_m": [1, 2]}]}, "position_tank_m must be 3"),
        ({"targets": [{"position_tank_m": [1, 2, "x"]}]}, "position_tank_m must be numbers"),
        ({"pings": [{"pose": [1, 2], "targets": []}]}, r"pings\[0\].pose"),
        ({"foo": 1}, "expected a 'pings' or 'targets' field"),
    ],
)
def test_bad_results_name_the_field(data, message):
    with pytest.raises(InputError, match=message):
        parse_results(data, SonarHead())


def test_results_file_errors(tmp_path):
    bad = tmp_path / "r.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_results(bad, SonarHead())
    with pytest.raises(InputError, match="not found"):
        load_results(tmp_path / "missing.json", SonarHead())


def test_error_ellipsoids_have_the_covariance_axes_times_n_sigma_and_magnification():
    cov = np.diag([1e-6, 4e-6, 0.25e-6])  # sigmas 1, 2, 0.5 mm
    est = [EstimateMarker(np.array([3.0, 1.0, 0.5]), cov, "point")]
    truth = [TruthMarker(np.array([3.001, 1.0, 0.5]), "post-1")]
    layers = {layer.name: layer for layer in estimate_layers(est, truth, n_sigma=2.0, view_size_m=9.5)}
    assert set(layers) == {"estimates", "estimate-ellipsoids", "truth", "estimate-errors"}
    # Largest 2-sigma semi-axis 4 mm; 2 % of 9.5 m is 190 mm -> magnification 50 (1-2-5 steps).
    ellipsoid = layers["estimate-ellipsoids"]
    assert "x50" in ellipsoid.label
    half = 0.5 * (np.asarray(ellipsoid.mesh.bounds).reshape(3, 2) @ np.array([-1.0, 1.0]))
    np.testing.assert_allclose(half, 50 * 2 * np.sqrt(np.diag(cov)), rtol=1e-2)  # sphere mesh poles/equator
    fixed = {layer.name: layer for layer in estimate_layers(est, truth, magnification=1.0)}
    assert "x" not in fixed["estimate-ellipsoids"].label.split("ellipsoids")[-1]


# -------------------------------------------------------------------------------------- cameras
def test_camera_presets_frame_the_tank():
    bounds = Tank().bounds_m
    top = camera_preset("top", bounds, aspect=1.5)
    assert top.parallel and top.view_up == (0.0, 1.0, 0.0)
    assert top.position_m[2] > bounds[1, 2] and top.position_m[:2] == top.focal_point_m[:2]
    # The 9 m length fits the width of a 1.5:1 window: half-height * aspect >= 4.5 m.
    assert top.parallel_scale_m * 1.5 >= 4.5
    # The visible height contains the 3 m width.
    assert top.focal_point_m[1] - top.parallel_scale_m <= 0.0 and top.focal_point_m[1] + top.parallel_scale_m >= 3.0
    side = camera_preset("side", bounds)
    assert side.view_up == (0.0, 0.0, 1.0) and side.position_m[1] < 0
    sonar = SonarHead(yaw_deg=30.0)
    view = camera_preset("sonar", bounds, sonar=sonar)
    direction = np.subtract(view.focal_point_m, view.position_m)
    assert np.dot(direction / np.linalg.norm(direction), sonar.boresight) > 0.99
    with pytest.raises(InputError, match="unknown preset 'front'"):
        camera_preset("front", bounds)


# ------------------------------------------------------------------------- rendering off-screen
@pytest.fixture(scope="module")
def tank_with_paths():
    scenes_builtin = pytest.importorskip("scenes.builtin")
    from acoustisim.propagation import SolverConfig, solve

    scene = scenes_builtin.builtin_scene("thesis-tank")
    paths = solve(scene, scene.sonar, SolverConfig(max_order=2, mechanisms=("direct", "specular", "edge")))
    return scene, paths


def _colour_count(image: np.ndarray, step: int = 32) -> int:
    quantised = (image[..., :3] // step).reshape(-1, 3)
    return len(np.unique(quantised, axis=0))


def test_off_screen_render_is_not_blank_and_has_the_actors(tank_with_paths, tmp_path):
    from acoustisim.viz.actors import KIND_COLORS
    from acoustisim.viz.render import ViewOptions, show_scene

    scene, paths = tank_with_paths
    results = [EstimateMarker(np.array([3.0, 1.2, 0.5]), np.diag([1e-6, 1e-6, 1e-6]), "point")]
    plotter = show_scene(scene, paths, results, options=ViewOptions(echo=0), camera="top", off_screen=True,
                         window_size=(600, 400))
    try:
        names = set(plotter.actors)
        expected = {"tank-walls", "tank-outline", "free-surface", "sonar-head", "transducer-left",
                    "transducer-centre", "transducer-right", "beam-3db", "beam-side-lobe", "paths-specular",
                    "paths-edge", "tof-left", "tof-ellipse-centre", "estimates", "estimate-ellipsoids", "truth",
                    "legend", "title"} | {f"object:{obj.name}" for obj in scene.objects}
        assert expected <= names, expected - names
        image = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    assert image.shape[:2] == (400, 600)
    # Not blank: a white page with a few lines would have std < 10 and a handful of colours.
    assert image[..., :3].std() > 20
    assert _colour_count(image) > 30
    # The specular paths' blue is on screen (some pixel within 40 of it on every channel).
    blue = np.round(np.asarray(KIND_COLORS[PathKind.SPECULAR]) * 255)
    assert np.any(np.all(np.abs(image[..., :3].astype(float) - blue) < 40, axis=-1))


def test_render_png_and_view_command(tank_with_paths, tmp_path, capsys):
    from acoustisim.cli.main import main

    results = tmp_path / "results.json"
    results.write_text(json.dumps({"targets": [{"range_m": 2.0, "bearing_deg": -8.5, "range_std_m": 0.002,
                                                "bearing_std_deg": 0.3}]}))
    out = tmp_path / "view.png"
    code = main(["view", "thesis-tank", "--png", str(out), "--camera", "side", "--size", "480x320",
                 "--results", str(results), "--max-order", "1"])
    assert code == 0
    assert capsys.readouterr().out.strip() == str(out)
    from PIL import Image

    image = np.asarray(Image.open(out))
    assert image.shape[:2] == (320, 480) and image[..., :3].std() > 10
    # Bad input: one line, exit 2.
    results.write_text("[{\"class\": \"point\"}]")
    assert main(["view", "thesis-tank", "--png", str(out), "--results", str(results), "--no-paths"]) == 2
    err = capsys.readouterr().err
    assert "no position" in err and len(err.strip().splitlines()) == 1
    assert main(["view", "thesis-tank", "--png", str(out), "--no-paths", "--echo", "0"]) == 2
    assert "need paths" in capsys.readouterr().err


def test_ping_file_gives_pose_paths_and_truth(tmp_path):
    import h5py

    from binsonar.recording import Recording, write_recording

    from acoustisim.viz.ping_file import load_ping

    sonar = SonarHead()
    paths = _hand_paths(sonar)
    recording = Recording(np.zeros((1, 3, 16)), 20e6, pose=np.array([[2.0, 1.0, 0.4, 15.0, 0.0, 0.0]]),
                          sound_speed_m_s=C_WATER)
    objects = json.dumps([{"name": "post-1", "position_m": [3.0, 1.5]}, {"name": "ball", "position_m": [4, 1, 0.3]}])
    path = write_recording(tmp_path / "ping.h5", recording, truth={
        "arrivals": paths.arrivals(), "surface_names": np.array(paths.surface_names, dtype=h5py.string_dtype()),
        "objects": objects})
    view = load_ping(path, sonar)
    assert view.sonar.position_m == (2.0, 1.0, 0.4) and view.sonar.yaw_deg == 15.0
    assert len(view.paths) == len(paths.arrivals()) and view.paths.surface_names == paths.surface_names
    np.testing.assert_allclose(np.sort(view.paths["delay_s"]), np.sort(paths.arrivals()["delay_s"]))
    # A 2-D position is placed at the transmitter's height.
    np.testing.assert_allclose(view.truths[0].position_m, [3.0, 1.5, 0.4])
    assert view.truths[1].name == "ball"
    with pytest.raises(InputError, match="ping 3 out of range"):
        load_ping(path, sonar, 3)


def test_free_field_scene_bounds_and_no_tank_layers():
    from acoustisim.viz.actors import scene_bounds, tank_layers

    scene = Scene("free", tank=None, sonar=SonarHead(position_m=(0.0, 0.0, 0.0)))
    bounds = scene_bounds(scene)
    assert np.all(bounds[0] < 0) and np.all(bounds[1] > 0)
    assert tank_layers(scene) == []
