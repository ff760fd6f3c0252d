"""Every cycle model: state layout, charge initialisation, exact mass balance, Jacobian."""

import numpy as np
import pytest

from pymc_vcc.physics.cycles import CYCLE_MODELS, cycle_model
from pymc_vcc.physics.cycles.base import (
    Block,
    BlockKind,
    InputLayout,
    InputSpec,
    OutputLayout,
    StateLayout,
)
from pymc_vcc.physics.refrigerant import load_refrigerant
from pymc_vcc.physics.unit import HEAT_PUMP_UNIT, load_unit

# (unit file, inputs at which each is checked): valve, speed Hz, outdoor K, indoor K, indoor RH
CASES = {
    "split-cooling": (None, np.array([0.40, 55.0, 308.15, 300.15, 0.0])),
    "heat-pump-heating": (HEAT_PUMP_UNIT, np.array([0.30, 65.0, 281.15, 293.15, 0.0])),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def setup(request):
    path, inputs = CASES[request.param]
    unit = load_unit(path)
    model = unit.cycle_model
    assert model.name == request.param
    tables = load_refrigerant(unit.refrigerant).tables
    c = model.constants(unit, unit.parameters.nominal)
    y = model.initial_state(c, unit.discretisation.n_volumes, inputs, tables)
    return unit, model, tables, c, y, inputs


def test_every_shipped_cycle_is_tested():
    assert set(CASES) == set(CYCLE_MODELS)


@pytest.mark.parametrize("name", sorted(CASES))
def test_state_layout_covers_every_index_once(name):
    model = cycle_model(name)
    for n in (3, 10):
        layout = model.layout(n)
        covered = np.zeros(layout.size, dtype=int)
        for block in layout.blocks:
            covered[layout[block.name]] += 1
        assert np.all(covered == 1)
        assert layout.n_cells == sum(
            block.size for block in layout.blocks if block.kind is BlockKind.ENTHALPY
        )


def test_layout_zones_and_errors():
    layout = StateLayout(
        [
            Block("p", 1, BlockKind.PRESSURE),
            Block("h", 3, BlockKind.ENTHALPY),
            Block("T", 3, BlockKind.TEMPERATURE),
            Block("q", 1, BlockKind.PRESSURE),
            Block("g", 2, BlockKind.ENTHALPY),
        ]
    )
    assert layout.zones.tolist() == [[0, 3], [7, 2]]
    assert layout["T"] == slice(4, 7) and layout.record["g"] == 8
    with pytest.raises(ValueError, match="must follow its zone's pressure"):
        StateLayout([Block("T", 2, BlockKind.TEMPERATURE), Block("h", 2, BlockKind.ENTHALPY)])
    with pytest.raises(ValueError, match="distinct names"):
        StateLayout([Block("p", 1, BlockKind.PRESSURE), Block("p", 1, BlockKind.PRESSURE)])
    with pytest.raises(KeyError, match="unknown state block 'x'"):
        layout.start("x")


def test_input_and_output_layouts_name_every_offset():
    outputs = OutputLayout(
        {"TA": ("a temperature", "K")},
        {"M": ("mass", "kg"), "W": ("a power", "W")},
        optional=("W",),
    )
    assert (outputs.offsets.TA, outputs.offsets.M, outputs.offsets.W) == (0, 1, 2)
    assert outputs.size == 3 and outputs.output_ids == ("TA",)
    assert outputs.measurable_info == {"TA": ("a temperature", "K"), "W": ("a power", "W")}
    with pytest.raises(ValueError, match="optional outputs must be diagnostics"):
        OutputLayout({"TA": ("a", "K")}, {}, optional=("TA",))
    with pytest.raises(ValueError, match="both outputs and diagnostics"):
        OutputLayout({"TA": ("a", "K")}, {"TA": ("a", "K")})
    speed = InputSpec("speed", "a speed", "Hz", 10.0, 150.0)
    humidity = InputSpec("rh", "a humidity", "1", 0.0, 1.0, default=0.0)
    inputs = InputLayout([speed, humidity])
    assert inputs.required_ids == ("speed",) and inputs.defaults == {"rh": 0.0}
    assert inputs.offsets.rh == 1 and inputs["speed"] is speed
    with pytest.raises(ValueError, match="required inputs come before the optional ones"):
        InputLayout([humidity, speed])


def test_unknown_cycle_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown cycle 'chiller'; allowed cycles are"):
        cycle_model("chiller")


@pytest.mark.parametrize("charge", [0.9, 1.3, 2.2])
def test_initial_state_holds_exactly_m0(setup, charge):
    unit, model, tables, _, _, inputs = setup
    c = model.constants(unit, unit.parameters.vector({"M0": charge}))
    y = model.initial_state(c, unit.discretisation.n_volumes, inputs, tables)
    assert model.total_mass(y, c, tables) == pytest.approx(charge, rel=1e-12)


def test_charge_that_does_not_fit_is_an_error(setup):
    unit, model, tables, _, _, inputs = setup
    c = model.constants(unit, unit.parameters.vector({"M0": 9.0}))
    with pytest.raises(ValueError, match="cannot be placed"):
        model.initial_state(c, unit.discretisation.n_volumes, inputs, tables)


def test_mass_changes_only_by_the_controller_source(setup):
    _, model, tables, c, y, inputs = setup
    c = c.copy()
    c[0]["controller"]["m0"] *= 1.01  # a mass error, so the source is non-zero
    y = y.copy()
    y[-1] = 0.3  # and an integral term
    dydt = np.empty(y.size)
    out = np.empty(model.n_eval)
    assert model.evaluate(y, inputs, c, tables, dydt, out)
    source = out[model.outputs.offsets.mdot_src]
    assert abs(source) > 1e-5
    eps = 1e-3
    rate = (
        model.total_mass(y + eps * dydt, c, tables) - model.total_mass(y - eps * dydt, c, tables)
    ) / (2 * eps)
    # exact up to the finite difference: a millionth of the compressor flow
    assert rate == pytest.approx(source, abs=1e-6 * out[model.outputs.offsets.MDOT])


def test_controller_switch_and_gains(setup):
    unit, model, _, _, _, _ = setup
    on = model.constants(unit, unit.parameters.nominal)[0]["controller"]
    off = model.constants(unit, unit.parameters.nominal, controller=False)[0]["controller"]
    assert on["kp"] == unit.controller.kp and on["ki"] == pytest.approx(on["kp"] ** 2 / 4)
    assert off["kp"] == 0.0 and off["ki"] == 0.0


def test_jacobian_matches_central_differences(setup):
    _, model, tables, c, y, inputs = setup
    dydt = np.empty(y.size)
    out = np.empty(model.n_eval)
    model.evaluate(y, inputs, c, tables, dydt, out)
    jac = model.jacobian(y, inputs, c, tables, dydt.copy())
    for j in (0, 3, 12, 22, 30, y.size - 1):
        step = 1e-6 * max(abs(y[j]), 1.0)
        up, down = np.empty(y.size), np.empty(y.size)
        shifted = y.copy()
        shifted[j] += step
        model.evaluate(shifted, inputs, c, tables, up, out)
        shifted[j] -= 2 * step
        model.evaluate(shifted, inputs, c, tables, down, out)
        central = (up - down) / (2 * step)
        scale = np.abs(central).max() + 1e-12
        assert np.max(np.abs(jac[:, j] - central)) < 1e-3 * scale


def _every_coupling_active(setup):
    """The Jacobian with a charge error, an integral term and rain on the indoor coil (every
    source active), and the forward difference of the whole right-hand side in column j with
    the Jacobian's step."""
    _, model, tables, c, y, inputs = setup
    c = c.copy()
    c[0]["controller"]["m0"] *= 1.01
    y = y.copy()
    y[-1] = 0.3
    inputs = inputs.copy()
    inputs[4] = 0.6
    f0, out = np.empty(y.size), np.empty(model.n_eval)
    model.evaluate(y, inputs, c, tables, f0, out)
    jac = model.jacobian(y, inputs, c, tables, f0.copy())

    def column(j):
        step = 1e-7 * max(abs(y[j]), 1.0)
        shifted, f = y.copy(), np.empty(y.size)
        shifted[j] += step
        model.evaluate(shifted, inputs, c, tables, f, out)
        return (f - f0) / step

    return jac, column


def test_wall_columns_reach_only_their_row_and_zone(setup):
    """The Jacobian shares evaluations between columns of the two zones: that is exact only
    if a wall temperature moves nothing outside its own row and its zone (with rain on the
    indoor coil, a charge error and an integral term, so every source is active)."""
    unit, model = setup[:2]
    layout = model.layout(unit.discretisation.n_volumes)
    jac, column = _every_coupling_active(setup)
    for block, (p_index, cells) in (("Tw_cond", layout.zones[0]), ("Tw_evap", layout.zones[1])):
        for j in range(layout[block].start, layout[block].stop):
            alone = column(j)
            reached = np.flatnonzero(alone)
            assert set(reached) <= {j, *range(p_index, p_index + cells + 1)}, (block, j)
            np.testing.assert_allclose(jac[:, j], alone, rtol=1e-9, atol=0.0)


def test_out_of_range_state_is_flagged_not_raised(setup):
    _, model, tables, c, y, inputs = setup
    y = y.copy()
    y[0] = 80e5  # above the critical pressure
    dydt = np.empty(y.size)
    out = np.empty(model.n_eval)
    assert not model.evaluate(y, inputs, c, tables, dydt, out)
    assert np.isnan(out).all()


def test_jacobian_is_the_dense_forward_difference(setup):
    """The Jacobian differences most columns with the flows between the zones held and adds
    their reach through the cell sums; every column still equals the plain forward difference
    of the whole right-hand side with the same step (with a charge error, an integral term and
    rain on the indoor coil, so that every coupling is active)."""
    jac, column = _every_coupling_active(setup)
    dense = np.column_stack([column(j) for j in range(jac.shape[1])])
    scale = np.abs(dense).max(axis=1, keepdims=True)
    assert np.all(np.abs(jac - dense) <= 1e-6 * scale)
