"""Reflection coefficients of the material library: the fluid, idealised and fixed models,
the library's values (the elastic model: ``test_materials_elastic.py``)."""

from dataclasses import replace

import numpy as np
import pytest

from acoustisim.errors import InputError
from acoustisim.materials import Material, get_material, material_library
from acoustisim.medium import Medium

WATER = Medium(water="fresh", temperature_c=20.0)
RHO_W, C_W = WATER.density, WATER.sound_speed


def as_fluid(name):
    """The library material reflecting by the fluid-fluid model (its shear ignored)."""
    return replace(get_material(name), model="fluid")


@pytest.mark.parametrize("name, handbook", [("pvc", 0.38), ("concrete", 0.72), ("glass", 0.81), ("steel", 0.94)])
def test_normal_incidence_against_handbook(name, handbook):
    # Handbook R values (physics.md) are printed to 2 decimals and were computed for water of
    # Z = 1.48-1.50 MRayl; that spread moves R by < 0.006, so 0.01 is the honest tolerance.
    assert get_material(name).normal_reflection(RHO_W, C_W) == pytest.approx(handbook, abs=0.01)


def test_normal_incidence_is_impedance_formula():
    steel = as_fluid("steel")
    z1, z2 = RHO_W * C_W, steel.density_kg_m3 * steel.sound_speed_m_s
    assert steel.normal_reflection(RHO_W, C_W) == pytest.approx((z2 - z1) / (z2 + z1), rel=1e-12)


@pytest.mark.parametrize("name", ["steel", "pvc", "concrete", "glass"])
def test_fluid_model_reflects_totally_beyond_critical_angle(name):
    material = as_fluid(name)
    critical = np.arcsin(C_W / material.sound_speed_m_s)
    angles = np.linspace(critical + 1e-6, np.pi / 2 - 1e-6, 50)
    r = material.reflection_coefficient(np.cos(angles), RHO_W, C_W)
    np.testing.assert_allclose(np.abs(r), 1.0, atol=1e-12)  # exact in the model: rounding only
    below = material.reflection_coefficient(np.cos(np.linspace(0.0, critical - 1e-3, 20)), RHO_W, C_W)
    assert np.all(np.abs(below) < 1.0)


@pytest.mark.parametrize("name", ["steel", "pvc", "concrete", "rubber"])
def test_energy_is_conserved_below_critical_angle(name):
    # Independent invariant: reflected + transmitted normal intensity flux = incident,
    # |R|^2 + (Z1 cos t2 / (Z2 cos t1)) |1 + R|^2 = 1 (fluid-fluid interface, real cos t2).
    material = as_fluid(name)
    sin_crit = min(C_W / material.sound_speed_m_s, 1.0)
    theta1 = np.linspace(0.0, np.arcsin(sin_crit) * 0.999, 40)
    r = material.reflection_coefficient(np.cos(theta1), RHO_W, C_W)
    sin2 = material.sound_speed_m_s / C_W * np.sin(theta1)
    cos2 = np.sqrt(1.0 - sin2**2)
    z1, z2 = RHO_W * C_W, material.density_kg_m3 * material.sound_speed_m_s
    flux = np.abs(r) ** 2 + (z1 * cos2) / (z2 * np.cos(theta1)) * np.abs(1.0 + r) ** 2
    np.testing.assert_allclose(flux, 1.0, atol=1e-12)


def test_water_against_water_does_not_reflect():
    water = Material("water", RHO_W, C_W)
    np.testing.assert_allclose(water.reflection_coefficient(np.linspace(0.01, 1.0, 9), RHO_W, C_W), 0.0, atol=1e-12)


@pytest.mark.parametrize("model", ["fluid", "elastic"])
def test_grazing_incidence_gives_minus_one(model):
    # At grazing incidence (cos t1 = 0, Z_w infinite) both formulas give R = -1 for any contrast,
    # whatever the losses (numerator -a_L, denominator a_L): to the rounding of one complex
    # division (a few 1e-16).
    pvc = replace(get_material("pvc"), model=model)
    assert abs(pvc.reflection_coefficient(0.0, RHO_W, C_W) + 1.0) < 1e-15


def test_idealised_and_fixed_models():
    cos = np.linspace(0.0, 1.0, 5)
    np.testing.assert_array_equal(get_material("rigid").reflection_coefficient(cos, RHO_W, C_W), 1.0)
    np.testing.assert_array_equal(get_material("pressure-release").reflection_coefficient(cos, RHO_W, C_W), -1.0)
    np.testing.assert_array_equal(get_material("pvc-pipe-air").reflection_coefficient(cos, RHO_W, C_W), -0.9)
    np.testing.assert_array_equal(get_material("pvc-pipe-water").reflection_coefficient(cos, RHO_W, C_W), 0.35)


def test_library_holds_the_required_materials():
    required = {"concrete", "glass", "pvc", "steel", "pvc-pipe-air", "pvc-pipe-water", "rubber", "rigid",
                "pressure-release"}
    library = material_library()
    assert required <= set(library)
    assert all(library[name].name == name for name in library)
    assert all(0.0 <= m.diffuse_mu <= 1.0 / np.pi for m in library.values())


def test_unknown_material_names_the_known_ones():
    with pytest.raises(InputError, match="wood.*known: .*steel"):
        get_material("wood")
    # scene materials are searched first and named among the known ones
    lab = Material("pvc-lab", 1380.0, 2380.0, 1060.0)
    assert get_material("pvc-lab", (lab,)) is lab
    with pytest.raises(InputError, match="known: .*pvc-lab"):
        get_material("wood", (lab,))


@pytest.mark.parametrize("name", ["pvc", "steel", "aluminium", "glass", "concrete"])
def test_builtin_solids_carry_elastic_values_and_losses(name):
    material = get_material(name)
    assert material.is_solid and material.compressional_speed_m_s == material.sound_speed_m_s
    # Poisson's ratio from the speeds lies in the physical range of these solids (0.2-0.4):
    # a check that c_L and c_S were not swapped or mistyped.
    ratio = (material.shear_speed_m_s / material.sound_speed_m_s) ** 2
    poisson = (1.0 - 2.0 * ratio) / (2.0 * (1.0 - ratio))
    assert 0.2 < poisson < 0.4
    # Losses: small (eta << 1) and shear at least as lossy as compressional (Ono 2020), and
    # the passivity bound alpha_L / alpha_T >= 4 c_T^3 / (3 c_L^3) (Norris 2017), i.e.
    # eta_L / eta_S >= (4/3) (c_S / c_L)^2.
    eta_l, eta_s = material.compressional_loss_factor, material.shear_loss_factor
    assert 0.0 < eta_l <= eta_s < 0.1
    assert eta_l / eta_s >= 4.0 / 3.0 * ratio


@pytest.mark.parametrize(
    "kwargs",
    [{"shear_speed_m_s": -1.0}, {"shear_speed_m_s": 1400.0}, {"compressional_loss_factor": 2.5},
     {"shear_loss_factor": float("inf")}, {"roughness_rms_m": -1e-3}],
)
def test_bad_elastic_values_are_rejected_naming_the_field(kwargs):
    base = {"name": "x", "density_kg_m3": 1000.0, "sound_speed_m_s": 1500.0}
    (field,) = kwargs
    with pytest.raises(InputError, match=field):
        Material(**{**base, **kwargs})


@pytest.mark.parametrize(
    "kwargs",
    [{"density_kg_m3": -1.0}, {"sound_speed_m_s": float("nan")}, {"model": "magic"}, {"diffuse_mu": 0.5},
     {"model": "fixed", "fixed_reflection": 1.5}, {"model": "Elastic"}],
)
def test_bad_material_is_rejected(kwargs):
    base = {"name": "x", "density_kg_m3": 1000.0, "sound_speed_m_s": 1500.0}
    with pytest.raises(ValueError):
        Material(**{**base, **kwargs})


def test_machined_steel_is_steel_with_the_small_perturbation_mu():
    # The library value recomputed by the formula it came from (materials.py docstring): rms 3 um,
    # 500 kHz, c = 1482 m/s, 60 deg incidence. The library stores the formula's double (17 digits),
    # so they agree to rounding: 1e-14 allows a few ulp of platform libm differences in sin/sqrt/pi.
    from acoustisim.experiments.edge_scene import small_roughness_lambert_mu

    machined, steel = get_material("steel-machined"), get_material("steel")
    mu = small_roughness_lambert_mu(3e-6, 500e3, 1482.0, 60.0)
    assert machined.diffuse_mu == pytest.approx(mu, rel=1e-14)
    assert f"{machined.diffuse_mu:.2e}" == "1.93e-05"  # the value quoted in docstrings and README
    # The same metal: only the surface finish differs, so the (specular) reflection is the same.
    for field in ("density_kg_m3", "sound_speed_m_s", "shear_speed_m_s", "model", "fixed_reflection"):
        assert getattr(machined, field) == getattr(steel, field)
    # mu scales as h^2: the library's rough steel (0.002) is a face of about 31 um rms.
    h_rough = 3e-6 * np.sqrt(steel.diffuse_mu / mu)
    assert 28e-6 < h_rough < 33e-6
