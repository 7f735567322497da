"""A table point's settled-state file (:mod:`.warm_start`): its layout, suffix and meta,
read without the DEM, so that the cache (:mod:`.cache`) can clear stale states without
importing the DEM's run."""

from __future__ import annotations

import json
import zipfile
import zlib

import numpy as np

#: Layout of a state file; another is not read.
STATE_FORMAT = 1
#: Suffix of a state file in the point store's folder.
STATE_SUFFIX = ".state.npz"


class WarmStartError(ValueError):
    """A state that cannot be read or used (named with the reason)."""


#: what reading a damaged or foreign npz raises
_UNREADABLE = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error)


def read_meta(path) -> dict:
    """A state file's meta (without its arrays); WarmStartError where it cannot be read or
    has another layout."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
    except _UNREADABLE as e:
        raise WarmStartError(f"{path}: not a readable state ({type(e).__name__}: {e})") from None
    if not isinstance(meta, dict) or meta.get("format") != STATE_FORMAT:
        raise WarmStartError(f"{path}: state layout {meta.get('format') if isinstance(meta, dict) else None!r}; "
                             f"this version reads {STATE_FORMAT}")
    return meta
