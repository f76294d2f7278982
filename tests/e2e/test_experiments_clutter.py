"""The ``clutter`` experiment: ROC scoring against hand-made truth, and a tiny run's JSON and invariants."""

import json
from pathlib import Path

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.experiments import clutter
from acoustisim.experiments.clutter_scenes import MIN_GAP_M, cluttered_scene
from acoustisim.experiments.config import ExperimentConfig
from acoustisim.experiments.registry import experiment_names
from acoustisim.experiments.roc import roc_curve, score_echoes
from binsonar.detection.echo import Echo


def test_registered_and_helpers_are_not_experiments():
    names = experiment_names()
    assert "clutter" in names
    assert not {"roc", "clutter_scenes", "clutter-scenes"} & set(names)


def test_roc_curve_counts():
    # 4 targets: best scores 5, 2, (missed), 1.5; false alarms 3, 1.2, 1.1 over 2 pings.
    roc = roc_curve(np.array([5.0, 2.0, -np.inf, 1.5]), np.array([3.0, 1.2, 1.1]), n_pings=2)
    thr = np.asarray(roc["threshold"])
    pd = np.asarray(roc["pd"])
    fa = np.asarray(roc["fa_per_ping"])
    assert np.all(np.diff(pd) <= 0) and np.all(np.diff(fa) <= 0)
    # at threshold 0 every echo counts: 3 of 4 targets, 3 false alarms over 2 pings
    assert pd[0] == 0.75 and fa[0] == 1.5
    at_2 = np.flatnonzero(thr == 2.0)[0]
    assert pd[at_2] == 0.5 and fa[at_2] == 0.5
    assert pd[-1] == 0.25 and fa[-1] == 0.0


def _arrivals(rows):
    dtype = [("channel", "i4"), ("kind", "i4"), ("delay_s", "f8"), ("amplitude", "f8"), ("object_ids", "i4", (4,))]
    return np.array(rows, dtype=dtype)


def test_score_echoes_detection_explained_and_false_alarm():
    # Channel 0: a post's specular arrival at 1 ms and a floor arrival at 1.5 ms; a noise-free
    # envelope of 0.5 V around both, zero elsewhere; noise sigma 0.1 V; tolerance 5 us.
    names = ("floor", "post-0")
    arrivals = _arrivals([(0, 1, 1.0e-3, 1.0, (1, -1, -1, -1)), (0, 1, 1.5e-3, 0.3, (0, -1, -1, -1)),
                          (0, 3, 2.0e-3, 1e-4, (0, -1, -1, -1))])
    fs, n = 1e6, 3000
    env = np.zeros((3, n))
    env[0, 995:1006] = 0.5
    env[0, 1495:1506] = 0.5
    assert names[arrivals["object_ids"][0][0]] == "post-0"  # the surface index the rows use
    targets = [(0, "post-0", np.array([1.0e-3]))]
    echoes = [[Echo(0, 1.002e-3, 1.0, 20.0, 4.0), Echo(0, 1.5e-3, 1.0, 20.0, 2.5),
               Echo(0, 2.0e-3, 1.0, 20.0, 1.7), Echo(0, 2.5e-3, 1.0, 20.0, 1.3)], [], []]
    best, fa = score_echoes(echoes, targets, arrivals, env, 0.0, fs, np.full(3, 0.1), 5e-6)
    assert best.tolist() == [4.0]            # the post's echo
    # the floor echo is explained (arrival + envelope); the one at 2 ms has a diffuse arrival but
    # no energy above the noise, the one at 2.5 ms nothing: both are false alarms
    assert sorted(fa.tolist()) == [1.3, 1.7]


def test_scene_generator_is_seeded_and_spaced():
    a = cluttered_scene(8, np.random.default_rng(5), 5e-3)
    b = cluttered_scene(8, np.random.default_rng(5), 5e-3)
    assert [o.name for o in a.objects] == [o.name for o in b.objects]
    assert getattr(a.tank.floor_material, "name", a.tank.floor_material) == "sand"
    kinds = {o.kind for o in a.objects}
    assert kinds == {"post", "edge", "cylinder", "sphere"}
    pts = np.array([o.mesh.bounds.mean(axis=0)[:2] for o in a.objects])
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(len(pts)) * 10
    # mesh-bound centres move by at most ~0.1 m from the reference points (prisms), so the
    # 0.25 m gap leaves more than 0.05 m
    assert d.min() > MIN_GAP_M - 0.2


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("clutter")
    config = ExperimentConfig(name="clutter", out_dir=out, seed=2, trials=1, workers=1, progress=False,
                              options={"densities": "1,3", "snrs": "30", "detectors": "ca-cfar,dwt,threshold"})
    clutter.run(config).write()
    return out, json.loads((out / "results.json").read_text())


def test_tiny_run_fields_and_invariants(tiny):
    out, r = tiny
    assert r["experiment"] == "clutter"
    assert r["densities"] == [1, 3] and r["snrs_db"] == [30.0]
    assert r["clipped_pings"] == 0
    assert len(r["scenes"]) == 2
    assert set(r["summary"]["by_density"]) == {"1", "3"}
    for m in ("ca-cfar", "dwt", "threshold"):
        s = r["summary"]["all"][m]
        assert s["pings"] == 2 and s["targets"] > 0
        for key in ("nominal_pd", "pd_max"):
            assert 0.0 <= s[key] <= 1.0
        assert s["nominal_false_alarms_per_ping"] >= 0.0
        if s["localised_targets"]:
            assert 0.0 <= s["association_accuracy"] <= 1.0
            assert len(s["range_errors_m"]) == s["associated_targets"]
        roc = s["roc"]
        assert len(roc["threshold"]) == len(roc["pd"]) == len(roc["fa_per_ping"])
        assert np.all(np.diff(roc["threshold"]) > 0)
        assert np.all(np.diff(roc["pd"]) <= 0) and np.all(np.diff(roc["fa_per_ping"]) <= 0)
        assert s["time_per_ping_s"] > 0
        # the ladder: one operating point per setting, the nominal one among them
        assert len(s["ladder_pd"]) == len(s["ladder_fa_per_ping"]) == len(clutter.LADDER[m])
        assert all(0.0 <= v <= 1.0 for v in s["ladder_pd"])
        assert s["ladder_pd"][clutter.NOMINAL[m]] == pytest.approx(s["nominal_pd"])
        assert s["ladder_fa_per_ping"][clutter.NOMINAL[m]] == pytest.approx(s["nominal_false_alarms_per_ping"])
    # The matched filter + CFAR finds the on-axis objects' echoes at 30 dB: the ROC's best P_D is
    # well above zero (a broken truth matching or tolerance would give 0).
    cfar = r["summary"]["all"]["ca-cfar"]
    assert cfar["pd_max"] > 0.3
    # Against the feature that reflected, the matched filter's targets are millimetre-accurate (its
    # TOF CRLB is tens of micrometres here; 5 mm leaves room for overlapping echoes); the 10-20 cm
    # of a prism's rear edges would show if the errors were taken against the wrong feature.
    assert cfar["associated_targets"] > 0
    assert cfar["range_error_median_abs_m"] < 5e-3
    # elastic echoes: both runs (the default --elastic compare), the same targets and pings
    assert r["elastic"] == "compare" and r["scenes"][0]["elastic_echoes"]
    assert not r["scenes"][0]["without_elastic"]["elastic_echoes"]
    for m in ("ca-cfar", "dwt", "threshold"):
        s, w = r["summary"]["all"][m], r["summary_without_elastic"]["all"][m]
        assert s["pings"] == w["pings"] == 2 and s["targets"] == w["targets"]
        assert w["nominal_elastic_per_ping"] == 0 and w["elastic_targets"] == 0  # nothing rings without the step
        assert 0 <= s["elastic_ghosts"] <= s["elastic_targets"] <= s["localised_targets"]
        assert s["nominal_elastic_per_ping"] <= s["elastic_per_ping_most_permissive"]
    assert "Elastic echoes" in (out / "report.md").read_text()
    assert set(r["figures"]) == {"clutter_roc.png", "clutter_errors.png"}
    for name in r["figures"]:
        assert (out / name).stat().st_size > 10_000


def test_bad_options(tmp_path):
    def run(**options):
        clutter.run(ExperimentConfig(name="clutter", out_dir=tmp_path, trials=1, workers=1, progress=False,
                                     options=options))

    with pytest.raises(InputError, match="--detectors"):
        run(detectors="matched-ish")
    with pytest.raises(InputError, match="--densities"):
        run(densities="0")
    with pytest.raises(InputError, match="--snrs"):
        run(snrs="a,b")
    with pytest.raises(InputError, match="--elastic"):
        run(elastic="maybe")


@pytest.mark.slow
def test_full_run(tmp_path):
    clutter.run(ExperimentConfig(name="clutter", out_dir=tmp_path, workers=2, progress=False)).write()
    r = json.loads((Path(tmp_path) / "results.json").read_text())
    pd = {snr: r["summary"]["by_snr"][snr]["ca-cfar"]["pd_max"] for snr in r["summary"]["by_snr"]}
    assert pd["40"] >= pd["20"]  # more SNR, no fewer detections at the lowest threshold
