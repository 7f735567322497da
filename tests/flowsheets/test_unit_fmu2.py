"""The FMI 2.0 unit adapters on millfmu's FMI 2.0 base (millfmu.fmi.base2), driven in-process
as a host would: a refused parameter, a refused step, the FMU state in memory and serialized
(checksum, identity), each as the mill FMU answers it."""

from __future__ import annotations

import json

import pytest

from flowsheets.master import unit_configs
from flowsheets.spec import load_flowsheet

from .support import FLOWSHEETS

pytest.importorskip("pythonfmu")


@pytest.fixture(scope="module")
def tank_cfg():
    return next(cfg for kind, cfg in unit_configs(load_flowsheet(FLOWSHEETS / "circuit.toml")).values()
                if kind == "tank")


def _tank(tmp_path, cfg, wrapper):
    from flowsheets.unit_fmu import TankSlave

    (tmp_path / "unit.json").write_text(json.dumps(cfg))
    (tmp_path / "wrapper.txt").write_text(wrapper + "\n")
    cls = type("Tank_test", (TankSlave,), {})  # a class per FMU, as the built script makes one
    s = cls(instance_name="t", resources=str(tmp_path), visible=False, logger=None)
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    return cls, s


def _messages(s, status=None):
    return [m.msg for m in s.log_queue if status is None or m.status == status]


@pytest.mark.parametrize("wrapper", ["fixed", "stock"])
def test_a_refused_parameter_is_fmi2error_at_initialization_and_refuses_every_step(tmp_path, tank_cfg, wrapper):
    from millfmu.fmi.base2 import FMUCallError
    from pythonfmu.enums import Fmi2Status

    _, s = _tank(tmp_path, tank_cfg, wrapper)
    s.set_real([s._at["pump_mass_flow"]], [-1.0])
    said = "fmi2ExitInitializationMode: parameter pump_mass_flow = -1.0: must be >= 0 kg/s; every step will be refused"
    if wrapper == "fixed":  # raised, and the rebuilt wrapper logs its message as it is (once)
        with pytest.raises(FMUCallError) as e:
            s.exit_initialization_mode()
        assert str(e.value) == said and said not in _messages(s)
    else:  # pythonfmu's own wrapper would make an exception fmi2Fatal: logged only
        s.exit_initialization_mode()
        assert said in _messages(s, Fmi2Status.error)
    assert s.do_step(0.0, 1.0) is False
    assert _messages(s,
                     Fmi2Status.discard)[
                         -1] == "doStep at t = 0.0 s refused: parameter pump_mass_flow = -1.0: must be >= 0 kg/s"


@pytest.mark.parametrize("wrapper", ["fixed", "stock"])
def test_states_restore_exactly_and_damaged_or_foreign_ones_are_refused(tmp_path, tank_cfg, wrapper):
    from millfmu.fmi.base2 import FMUCallError

    cls, s = _tank(tmp_path, tank_cfg, wrapper)
    s.exit_initialization_mode()
    s.set_real([s._at["inlet1_mass_flow"]], [0.01])
    assert s.do_step(0.0, 1.0)
    state = s._get_fmu_state()
    blob = cls._fmu_state_to_bytes(state)
    assert s.do_step(1.0, 1.0)
    after = s.get_real(range(len(s._v)))
    s._set_fmu_state(state)
    assert s.do_step(1.0, 1.0) and s.get_real(range(len(s._v))) == after
    s._set_fmu_state(cls._fmu_state_from_bytes(blob))
    assert s.do_step(1.0, 1.0) and s.get_real(range(len(s._v))) == after
    # a step size <= 0 is refused like a bad input, the state kept
    assert s.do_step(2.0, 0.0) is False
    assert _messages(s)[-1] == ("doStep at t = 2.0 s refused, state unchanged: input communicationStepSize = 0.0: "
                                "must be finite and > 0 s")
    assert s.get_real(range(len(s._v))) == after
    i = blob.index(b'"t_s":') + len(b'"t_s":')
    edited = blob[:i] + (b"7" if blob[i:i + 1] != b"7" else b"8") + blob[i + 1:]
    other = type("Tank_other", (cls,), {})
    for bad, reader in ((edited, cls), (blob, other)):
        if wrapper == "fixed":
            with pytest.raises(FMUCallError, match="fmi2DeSerializeFMUstate"):
                reader._fmu_state_from_bytes(bad)
        else:
            s._set_fmu_state(reader._fmu_state_from_bytes(bad))
            assert "fmi2SetFMUstate: state refused, nothing applied" in _messages(s)[-1]
            assert s.get_real(range(len(s._v))) == after
    if wrapper == "fixed":  # raised: the rebuilt wrapper logs its message
        with pytest.raises(FMUCallError, match=r"malformed \(ValueError:"):
            s._set_fmu_state({**state, "values": state["values"][:-1]})
    else:
        s._set_fmu_state({**state, "values": state["values"][:-1]})
        assert "malformed (ValueError:" in _messages(s)[-1]
    assert s.get_real(range(len(s._v))) == after

