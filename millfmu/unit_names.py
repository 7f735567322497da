"""The unit-suffix convention of every key, parameter and variable, and the spellings of
earlier releases that scene files, stored tables and run folders may still hold.

A quantity's name ends in its SI unit: symbols in their own case (``Pa``, ``J``, ``W``), a
product joined by ``_`` (``viscosity_Pa_s``: Pa s), the denominator after ``_per_``
(``tip_speed_m_per_s``: m/s, ``density_kg_per_m3``: kg/m3, ``omega_rad_per_s``: rad/s,
``gravity_m_per_s2``: m/s2, ``collision_rate_per_m3_s``: 1/(m3 s)).

Earlier releases wrote some denominators without ``per`` (``tip_speed_m_s``,
``density_kg_m3``, ``omega_rad_s``, ``gravity_m_s2``, ``nu_m2_s``, ``flow_m3_s``) and
``viscosity_pa_s`` in lower case. :func:`modern_name` maps such a name to the current one;
readers of scene files, table files and run folders accept the old spellings for one
release, scene files with a note naming each key to change. Imports nothing of millfmu.
"""

from __future__ import annotations

import re
import warnings

# A suffix ends where the name does or where "__" or a non-alphanumeric character follows
# (stored array names join axis names with "__").
_END = r"(?![A-Za-z0-9])"
_START = r"(?<=[A-Za-z0-9])"
#: (earlier suffix, current suffix). A name's end is matched, so ``_m_s`` never takes the
#: ``_m_s`` of ``_m_s2``; ``_m3_s`` after ``per`` is 1/(m3 s) and was never renamed.
_SUFFIXES = [("_m_s2", "_m_per_s2"), ("_m_s", "_m_per_s"), ("_m2_s", "_m2_per_s"), ("_m3_s", "_m3_per_s"),
             ("_kg_m3", "_kg_per_m3"), ("_pa_s", "_Pa_s"), ("_rad_s", "_rad_per_s")]
_RULES = [(re.compile(_START + ("(?<!per)" if old == "_m3_s" else "") + old + _END), new) for old, new in _SUFFIXES]
#: The inverse, for names of the earlier release's key content (tables' and stored points'
#: keys): every such name was written the old way there.
_INVERSE = [(re.compile(_START + new + _END), old) for old, new in _SUFFIXES]


def modern_name(name: str) -> str:
    """``name`` with an earlier release's unit suffix written the current way (unchanged
    where it has none)."""
    for pat, rep in _RULES:
        name = pat.sub(rep, name)
    return name


def earlier_name(name: str) -> str:
    """``name`` as the earlier release wrote it (the inverse of :func:`modern_name` on names
    of that release)."""
    for pat, rep in _INVERSE:
        name = pat.sub(rep, name)
    return name


class GivenTwice(ValueError):
    """A key given in both spellings: ``where`` (its dotted path) = ``value``, and its
    current spelling ``current`` = ``current_value`` beside it."""

    def __init__(self, where: str, value, current: str, current_value):
        self.where, self.value, self.current, self.current_value = where, value, current, current_value
        super().__init__(f"{where}: given twice, also as {current!r} (its current spelling); give one")

    @property
    def allowed(self) -> str:
        """What a scene's refusal says after the key and its value."""
        return f"given twice, also as {self.current} = {self.current_value!r} (its current spelling); give one"


def _map_keys(obj, fn, renamed: list | None, path: str, value_keys, values: bool = False):
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            nk = fn(k) if isinstance(k, str) else k
            where = f"{path}.{k}" if path else str(k)
            if nk != k:
                if nk in obj:
                    raise GivenTwice(where, v, nk, obj[nk])
                if renamed is not None:
                    renamed.append((where, nk))
            out[nk] = _map_keys(v, fn, renamed, where, value_keys, nk in value_keys)
        return out
    if isinstance(obj, list):
        return [_map_keys(v, fn, renamed, f"{path}[{i}]", value_keys, values) for i, v in enumerate(obj)]
    if values and isinstance(obj, str):
        nv = fn(obj)
        if nv != obj and renamed is not None:
            renamed.append((f"{path} = {obj!r}", nv))
        return nv
    return obj


def modernize(obj, *, renamed: list | None = None, value_keys=()):
    """A copy of ``obj`` (JSON-like: dicts, lists, scalars) with every dict key, and the
    strings held by the keys ``value_keys`` (names, e.g. a list of table axes), in the current
    spelling. Each change is appended to ``renamed`` as (where, current name). A key given
    in both spellings is refused (ValueError naming it)."""
    return _map_keys(obj, modern_name, renamed, "", frozenset(value_keys))


def to_earlier(obj):
    """A copy of ``obj`` with every dict key as the earlier release wrote it."""
    return _map_keys(obj, earlier_name, None, "", frozenset())


def read_as_current(obj, what: str, *, value_keys=(), stacklevel: int = 1):
    """:func:`modernize` of ``obj`` read from ``what`` (a file or scene, named in the note),
    with a FutureWarning naming each key written in the earlier spelling and its current
    name (``stacklevel`` as :func:`warnings.warn` counts it from the caller); ValueError
    for a key given in both spellings."""
    renamed: list = []
    out = modernize(obj, renamed=renamed, value_keys=value_keys)
    if renamed:
        items = "; ".join(f"{where} -> {new}" for where, new in renamed)
        warnings.warn(f"{what}: unit suffixes in an earlier release's spelling, read as the current names ({items}); "
                      f"the old spelling is accepted in this release only", FutureWarning, stacklevel=stacklevel + 1)
    return out
