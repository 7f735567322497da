"""What the mill's FMI 2.0 and 3.0 adapters (:mod:`.mill2`, :mod:`.mill3`) share: the scene
and model an FMU starts from, the model for parameter values set before initialization,
the step, the words of a refused input, and the FMU state. Each standard's base
(:mod:`.base2`, :mod:`.base3`) turns these into its statuses; each adapter lays out its
variables and names them. No physics."""

from __future__ import annotations

import copy

from ..mill import InputError, MillModel, StepError
from ..scene import SceneError, scene_from_dict
from .variables import SCENE_FILE, model_with, plain, read_scene_dict


class MillAdapter:
    """Mixin of the mill's slaves. A subclass gives ``WARNING`` (its standard's warning
    status), ``_scene_key`` (position in the value list -> (section, key) of the values that
    are the scene's), ``_publish(outputs)``, ``_inputs()``, ``_input_name(model_name)`` and
    ``_scene_value_name(dotted_key)`` (the FMI variable of a model input or scene key)."""

    description = "Wet stirred media mill (bead mill): population balance with Kwade's stress model"
    REFUSED = (InputError, StepError)
    WARNING = None

    def _start_model(self):
        """The scene in the FMU's resources and its model; returns the scene."""
        self._warned: set = set()  # what the log said once (MillModel.new_warnings)
        self._scene_dict = read_scene_dict(self.resources)
        scene = scene_from_dict(self._scene_dict, SCENE_FILE)
        self.model = MillModel(scene, no_dem=True)  # an FMU carries no DEM: it never builds a table
        self._base_scene = scene
        self._overrides: dict = {}
        return scene

    # ---- life cycle ------------------------------------------------------------------------
    def _configure(self):
        """Values set before initialization ends are the scene's operating point: rebuild
        the model where they differ from the scene's; a value the scene refuses is refused
        by the variable's name (``refuse_configuration``)."""
        over = {}
        for at, (sec, key) in self._scene_key.items():
            x = self._v[at]
            if x != getattr(getattr(self._base_scene, sec), key):
                over[(sec, key)] = x
        model, error = self._model_for(over)
        if error is not None:
            self.refuse_configuration(error)
        self.model, self._overrides = model, dict(over)
        self._config_error = None
        self._publish(model.outputs())

    def _model_for(self, over: dict):
        """(model, None) for the scene with ``over`` {(section, key): value} applied, or
        (None, message naming the FMI variable) where the scene refuses it."""
        if over == self._overrides:
            return self.model, None
        try:
            model = model_with(self._scene_dict, over)  # a DEM table may refuse the scene's operating point
        except SceneError as e:
            return None, f"{self._scene_value_name(e.key)} = {e.value!r}: {e.allowed}"
        if model.grid.n != self.n_classes:  # pragma: no cover - no parameter changes the grid
            raise RuntimeError("size grid changed")
        return model, None

    def _take_step(self, h: float):
        outs = self.model.step(h, **self._inputs())
        self._publish(outs)
        for w in self.model.new_warnings(outs, self._warned):
            self.log(w, self.WARNING)

    def _refusal(self, e: Exception) -> str:
        if isinstance(e, InputError):
            name = "communicationStepSize" if e.name == "dt_s" else self._input_name(e.name)
            return f"input {name} = {e.value!r}: {e.allowed}"
        return str(e)

    # ---- FMU state -------------------------------------------------------------------------
    def _state(self) -> dict:
        return {"overrides": [[sec, key, x] for (sec, key), x in self._overrides.items()],
                "model": plain(self.model.get_state())}

    def _restore(self, state: dict):
        """The model of a state's parameter values with its state; ValueError (the base
        leaves everything as it was) where the scene refuses them."""
        over = {(sec, key): x for sec, key, x in state["overrides"]}
        model, error = self._model_for(over)
        if error is not None:
            raise ValueError(error)
        model.set_state(copy.deepcopy(state["model"]))
        self.model, self._overrides = model, over
