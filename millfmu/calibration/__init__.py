"""Calibration: fit scene constants to a user's measured batch grinding data, with intervals.

A material's breakage energy (and the share of a collision's energy that reaches a
particle) is what a process engineer pins with his own grinding test. :func:`calibrate`
fits one or two scene constants (:data:`FITTABLE`) to measured batch data at the scene's
operating point:

- residuals: ln(x_model / x_data) for characteristic sizes (``x10_m``, ``x50_m``,
  ``x90_m``), Q3_model(x) - Q3_data for full size distributions (``x_m``, ``Q3``), and
  f_model - f_data for the disrupted fraction of cells;
- scipy.optimize.least_squares on the logarithm of each constant, inside its physical
  bounds (eta_E in (0, 1]; the others > 0) and a search range of :data:`.fitting.SEARCH_DECADES`
  decades around the start;
- 95 % confidence intervals from the Jacobian at the optimum in log space, and the
  correlation of a pair. ``error_model="per_sample"`` (the default where a time has more than
  one value: x10/x50/x90 of one sample, or a Q3 curve) allows an error shared by all values
  of one sample (a laser-diffraction measurement shifts a sample's whole distribution): a
  cluster-robust (sandwich) covariance with one cluster per measurement time, the CR2
  small-sample correction (Bell & McCaffrey 2002; Pustejovsky & Tipton 2018) and Student's t
  with G - 1 degrees of freedom (G times). ``error_model="independent"`` (and data with one
  value per time) takes every value's error as independent: Gauss-Newton s^2 (J^T J)^-1,
  s^2 = sum r^2 / (n - p), Student's t with n - p degrees of freedom (Bates & Watts 1988,
  ch. 2). With shared errors the independent interval is too narrow (about 70 % coverage in
  the project's held-out study of x10/x50/x90 data);
- a lack-of-fit warning (:attr:`Calibration.lack_of_fit`) when the residuals are systematic:
  the per-time mean residual trends with time (Kendall's tau, exact, p < :data:`.intervals.LACK_OF_FIT_P`)
  or, for x10/x50/x90, one size column lies off the others at every time (F test of column
  terms against the scatter left by each time's mean and the Jacobian, p < :data:`.intervals.LACK_OF_FIT_P`).

A constant the data cannot pin is refused by name (:class:`CalibrationError`): its interval
spans more than :data:`.fitting.MAX_INTERVAL_FACTOR`, a pair's |correlation| exceeds
:data:`.fitting.MAX_CORRELATION`, it ends on a bound (which bound, and which constant to free
instead), the model does not respond to it, it lies on a plateau (the objective at the far
end of its search range is within the noise of the optimum: the data bound it on one side
only), or there are fewer values than constants.

A refusal names the arguments of :func:`calibrate` and scene keys; the command line
(``millfmu calibrate``, :mod:`.cli`) words it with its options.

The parts: :mod:`.measured` (reading and checking the data; :class:`CalibrationError`),
:mod:`.fitting` (the fittable constants, the model at the data, the fit and its refusals),
:mod:`.intervals` (error models, covariance, intervals, lack of fit), :mod:`.scene_file`
(writing ``calibrated.toml`` and ``calibration.json``), :mod:`.shipped` (seed 000's
one-datum calibration and the shipped calibrated pairs, :data:`SHIPPED`), :mod:`.cli` (the
command). Their public names are this package's.
"""


from .fitting import (FITTABLE, JAC_STEP, MAX_CORRELATION, MAX_INTERVAL_FACTOR, SEARCH_DECADES, Calibration, Constant,
                      Fitted, calibrate, with_values)
from .intervals import CLUSTER_CORRECTION, ERROR_MODELS, LACK_OF_FIT_MIN, LACK_OF_FIT_P
from .measured import MAX_SIZE_M, SIZE_COLUMNS, CalibrationError, Data, parse_data, read_data
from .scene_file import set_toml_values, write
from .shipped import (CONSTANTS, QUANTITIES, SHIPPED, Datum, Pair, batch_value, check, constant, example_scene, fit,
                      with_constant, with_model)

__all__ = [
    "CLUSTER_CORRECTION", "CONSTANTS", "ERROR_MODELS", "FITTABLE", "JAC_STEP", "LACK_OF_FIT_MIN", "LACK_OF_FIT_P",
           "MAX_CORRELATION",
    "MAX_INTERVAL_FACTOR", "MAX_SIZE_M", "QUANTITIES", "SEARCH_DECADES", "SHIPPED", "SIZE_COLUMNS", "Calibration",
    "CalibrationError", "Constant", "Data", "Datum", "Fitted", "Pair", "batch_value", "calibrate", "check", "constant",
    "example_scene", "fit", "parse_data", "read_data", "set_toml_values", "with_constant", "with_model", "with_values",
           "write",
]
