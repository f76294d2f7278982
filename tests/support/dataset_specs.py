"""The small dataset spec the dataset tests simulate, as TOML text (what a user writes).

the dataset tests (``tests/unit/test_dataset_tasks.py``, ``tests/e2e/test_dataset_{store,dask}.py``) build their specs with :func:`small_spec`; only the
[dataset] keys differ between them. (``tests/unit/test_dataset_spec.py`` keeps its own, larger spec:
it validates every object kind and edits its text line by line.)
"""

from __future__ import annotations


def small_spec(*, name: str, n_samples: int, seed: int, samples_per_chunk: int = 4, max_arrivals: int = 48) -> str:
    """TOML text of a fast spec: a 2 ms record, direct and first-order specular paths only.

    Each sample holds one or two spheres of class "ball" (steel or aluminium) and at most one
    PVC post, 0.3-1.2 m ahead of a head at x 0.8-1.2 m, y 1.2-1.8 m, yaw -10 to 10 degrees, with
    the strongest echo's SNR drawn from 10-30 dB. About 0.1 s of CPU a sample.

    Parameters
    ----------
    name : str
        ``dataset.name``.
    n_samples, seed, samples_per_chunk, max_arrivals : int
        The [dataset] keys of the same names.

    Returns
    -------
    str
        The spec, for :func:`acoustisim.datasets.spec.loads_spec` or a ``.toml`` file.
    """
    return f"""
[dataset]
name = "{name}"
n_samples = {n_samples}
seed = {seed}
max_arrivals = {max_arrivals}
samples_per_chunk = {samples_per_chunk}
[sonar]
x_m = [0.8, 1.2]
y_m = [1.2, 1.8]
yaw_deg = [-10.0, 10.0]
record_length_s = 0.002
[snr]
snr_db = [10.0, 30.0]
[solver]
max_order = 1
mechanisms = ["direct", "specular"]
diffuse_rays = 0
amplitude_floor_db = -60.0
[placement]
min_range_m = 0.3
max_range_m = 1.2
half_angle_deg = 15.0
[[objects]]
kind = "sphere"
class = "ball"
count = [1, 2]
radius_m = [0.02, 0.05]
materials = ["steel", "aluminium"]
[[objects]]
kind = "post"
count = [0, 1]
radius_m = [0.01, 0.03]
"""
