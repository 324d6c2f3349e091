"""Curves over time (Viaud & Yahia §4): named channels of keyframes, saved as JSON.

    {"format": "mimica-timeline/1", "duration": 2.0,
     "channels": {"zygomaticus_major_L": {"interp": "cubic", "keys": [[0, 0], [0.5, 1], [2, 0]]}}}

A channel is a muscle's activation, an external force or age; `interp` is "linear",
"cubic" (monotone Hermite: no overshoot between keys) or "step".
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..mesh import atomic_path, read_json

FORMAT = "mimica-timeline/1"
INTERPS = ("linear", "cubic", "step")
MAX_DURATION = 3600.0                         # seconds: an hour of animation at most
# the range of a channel's values: age in years, force scales, muscle activations
RANGES = {"age": (0.0, 150.0), "gravity": (-100.0, 100.0), "pull": (-100.0, 100.0)}
ACTIVATION_RANGE = (-2.0, 2.0)

# the six basic expressions and neutral as muscle activations (FACS action units mapped to
# the muscles that produce them, after Ekman & Friesen and Hjortsjö)
PRESETS = {
    "neutral": {},
    "happiness": {"zygomaticus_major": 1.0, "orbicularis_oculi": 0.3, "orbicularis_oculi_lower": 0.4},  # AU6+12
    "sadness": {"frontalis_medial": 0.6, "corrugator_supercilii": 0.5, "depressor_anguli_oris": 1.0,  # AU1+4+15
                "mentalis": 0.3},
    "surprise": {"frontalis": 0.6, "frontalis_medial": 0.6, "levator_palpebrae": 0.5,               # AU1+2+5+26
                 "digastric": 0.35, "depressor_labii_inferioris": 0.2},
    "anger": {"corrugator_supercilii": 1.0, "procerus": 0.6, "orbicularis_oris": 0.5,                 # AU4+5+7+23
              "orbicularis_oculi_lower": 0.6, "levator_palpebrae": 0.3},
    "disgust": {"levator_labii_superioris_alaeque_nasi": 0.6, "levator_labii_superioris": 0.4,  # AU9+10+15
                "depressor_anguli_oris": 0.4, "nasalis": 0.5, "procerus": 0.4},
    "fear": {"frontalis": 0.5, "frontalis_medial": 0.6, "corrugator_supercilii": 0.4,            # AU1+2+4+5+20+26
             "levator_palpebrae": 0.6, "risorius": 0.6, "digastric": 0.2},
}


@dataclass
class Channel:
    """One curve of a timeline: keyframes (time, value), interpolated between them.

    Attributes
    ----------
    keys : (k, 2) float array
        Time in seconds and value, times increasing; before the first key the first value holds,
        after the last the last.
    interp : str
        "step", "linear" or "cubic" (monotone: PCHIP, no overshoot between keys).
    """
    keys: np.ndarray            # (k, 2): time, value; times increasing
    interp: str = "linear"

    def __call__(self, t):
        """The curve at time(s) `t` (float or array of seconds), as an array of t's shape."""
        t = np.asarray(t, float)
        k = self.keys
        if len(k) == 1:
            return np.full_like(t, k[0, 1])
        if self.interp == "step":
            i = np.clip(np.searchsorted(k[:, 0], t, side="right") - 1, 0, len(k) - 1)
            return k[i, 1]
        if self.interp == "linear":
            return np.interp(t, k[:, 0], k[:, 1])
        from scipy.interpolate import PchipInterpolator
        return PchipInterpolator(k[:, 0], k[:, 1], extrapolate=False)(np.clip(t, k[0, 0], k[-1, 0]))


@dataclass
class Timeline:
    """Named curves over time: one channel per muscle (activation, about -1 to 1) or force
    ("age" in years, "gravity" and "pull" as scales), what `simulate` plays.  Saved as JSON
    ({"format": "mimica-timeline/1", "duration", "channels": {name: {"interp", "keys"}}}).

    Attributes
    ----------
    channels : dict of str to Channel
        The curves by name; a name without a channel is 0 throughout.
    duration : float
        Seconds.
    """
    channels: dict = field(default_factory=dict)
    duration: float = 1.0

    def values(self, t: float, names) -> np.ndarray:
        """(len(names),) float: each named channel at time `t` (0 where it has none)."""
        return np.array([float(self.channels[n](t)) if n in self.channels else 0.0 for n in names])

    @classmethod
    def preset(cls, expression: str, muscles, duration=2.0, onset=0.3, hold=None) -> "Timeline":
        """Ramp into an expression preset, hold it, and (if the clip is long) release it."""
        if expression not in PRESETS:
            raise MimicaError(f"unknown expression {expression!r}; presets: {', '.join(PRESETS)}")
        onset = min(onset, 0.4 * duration)
        hold = duration * 0.6 if hold is None else hold
        from ..rig.muscles import weights_on
        ch = {}
        for name, a in zip(muscles, weights_on(PRESETS[expression], list(muscles))):
            if a:
                keys = [[0.0, 0.0], [onset, a]]
                if onset + hold + 0.2 < duration:              # long enough to let go again
                    keys += [[onset + hold, a], [duration, 0.0]]
                ch[name] = Channel(np.array(keys), "cubic")
        return cls(ch, duration)

    @classmethod
    def action(cls, action: str, muscles, duration=2.0, onset=0.3) -> "Timeline":
        """Ramp into one facial action (FACS unit, rig.muscles.FACIAL_ACTIONS) and hold it."""
        from ..rig.muscles import action_activations
        act = action_activations(action, list(muscles))
        ramp = min(onset, duration / 3)
        return cls({n: Channel(np.array([[0.0, 0.0], [ramp, v]]), "cubic") for n, v in zip(muscles, act) if v},
                   duration)

    def save(self, path) -> Path:
        """Write the timeline as JSON, whole or not at all; returns the path."""
        doc = {"format": FORMAT, "duration": self.duration,
               "channels": {n: {"interp": c.interp, "keys": c.keys.tolist()} for n, c in self.channels.items()}}
        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(doc, indent=1) + "\n")
        return path

    @classmethod
    def load(cls, path) -> "Timeline":
        """A timeline file read and checked: each channel's keys finite, times increasing, values
        in the channel's range (RANGES, else ACTIVATION_RANGE); a MimicaError naming the file and
        the channel otherwise."""
        path = Path(path)
        doc = read_json(path, "timeline")
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise MimicaError(f"{path}: expected a timeline with 'format': '{FORMAT}'")
        chans = {}
        channels = doc.get("channels") or {}
        if not isinstance(channels, dict):
            raise MimicaError(f"{path}: 'channels' must be an object {{name: {{'keys': [[time, value], ...]}}}}")
        for name, c in channels.items():
            try:
                keys = np.asarray(c["keys"], float)
                interp = c.get("interp", "linear")
            except (TypeError, KeyError, ValueError, AttributeError, IndexError):
                raise MimicaError(f"{path}: channel {name!r} needs 'keys': [[time, value], ...]") from None
            if keys.ndim != 2 or keys.shape[1] != 2 or len(keys) == 0 or not np.isfinite(keys).all():
                raise MimicaError(f"{path}: channel {name!r}: keys must be [[time, value], ...] with finite numbers")
            lo, hi = RANGES.get(name, ACTIVATION_RANGE)
            if keys[:, 1].min() < lo or keys[:, 1].max() > hi:
                raise MimicaError(f"{path}: channel {name!r}: values must lie in [{lo:g}, {hi:g}]")
            if (np.diff(keys[:, 0]) <= 0).any():
                raise MimicaError(f"{path}: channel {name!r}: key times must increase")
            if interp not in INTERPS:
                raise MimicaError(f"{path}: channel {name!r}: interp {interp!r} is not one of {', '.join(INTERPS)}")
            chans[name] = Channel(keys, interp)
        last = max((c.keys[-1, 0] for c in chans.values()), default=0.0)
        dur = doc.get("duration", last if last > 0 else 1.0)
        if isinstance(dur, bool) or not isinstance(dur, (int, float)) or not 0 < dur <= MAX_DURATION:
            raise MimicaError(f"{path}: duration must be a number of seconds in (0, {MAX_DURATION:g}]")
        return cls(chans, float(dur))
