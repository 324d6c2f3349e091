"""The muscle library: each muscle defined once relative to the 68 iBUG landmarks.

A linear muscle is a thin strip from its origin (on the skull, deeper) to its insertion
(under the skin).  Points are weighted sums of landmarks; `lift` moves a point up along the
face (in eye-to-eye widths) and `out` sideways, away from the mid-line.  Depths are in
eye-to-eye widths below the skin.  Subject's right = landmarks 0-8 side ("_R").
Anatomy after Hjortsjö and Kim 2020 §IV (zygomaticus major, corrugator supercilii,
depressor labii inferioris, depressor anguli oris) and Viaud & Yahia 1992 §4.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..store import shape_names


@dataclass(frozen=True)
class MuscleDef:
    """A muscle of the library, placed on any face by its landmarks.

    Attributes
    ----------
    name : str
    origin, insertion : dict
        Landmark index -> weight: the ends as weighted means of landmarks.
    origin_lift, insertion_lift : float
        Moved along the face's up axis, in eye widths.
    origin_out, insertion_out : float
        Moved sideways, away from the mid-line, in eye widths.
    width : float
        The strip's width, eye widths.
    origin_depth, insertion_depth : float
        Under the skin, eye widths.
    alpha : float or None
        Kim eq. 19's ROI range for this muscle (None: the rig's).
    contraction : float or None
        Shortening at full activation (None: the rig's).
    """
    name: str
    origin: dict                  # landmark index -> weight
    insertion: dict
    origin_lift: float = 0.0      # along the face's up axis, in eye widths
    insertion_lift: float = 0.0
    origin_out: float = 0.0       # sideways, away from the mid-line, in eye widths
    insertion_out: float = 0.0
    width: float = 0.12           # strip width, eye widths
    origin_depth: float = 0.10
    insertion_depth: float = 0.04
    alpha: float | None = None    # Kim eq. 19 ROI range for this muscle (None: the rig's)
    contraction: float | None = None   # shortening at full activation (None: the rig's)


def _mirror(d: MuscleDef) -> MuscleDef:
    """Left-side twin of a right-side muscle (iBUG left/right landmark pairs)."""
    from ..landmarks import MIRROR
    mir = lambda w: {int(MIRROR[k]): v for k, v in w.items()}  # noqa: E731
    return MuscleDef(d.name[:-2] + "_L", mir(d.origin), mir(d.insertion), d.origin_lift, d.insertion_lift,
                     d.origin_out, d.insertion_out, d.width, d.origin_depth, d.insertion_depth, d.alpha,
                     d.contraction)


_RIGHT = [
    # Kim 2020's four (placement and ROI range calibrated on the ICT generic face against
    # its sculpted shapes, see bench/simulate.py)
    MuscleDef("zygomaticus_major_R", {0: 0.7, 1: 0.3}, {48: 1.0}, origin_lift=0.05, origin_out=-0.2,
              insertion_out=0.05, width=0.14, alpha=16),
    MuscleDef("corrugator_supercilii_R", {21: 1.0}, {18: 0.5, 19: 0.5}, origin_lift=-0.4, width=0.3,
              origin_depth=0.1, alpha=18),
    MuscleDef("depressor_labii_inferioris_R", {7: 0.7, 6: 0.3}, {58: 0.6, 59: 0.4}, origin_lift=-0.05,
              width=0.12, alpha=10),
    MuscleDef("depressor_anguli_oris_R", {5: 0.6, 6: 0.4}, {48: 1.0}, origin_lift=-0.1, width=0.14, alpha=9),
    # the rest of Viaud & Yahia's list (linear approximations; sphincters as strips)
    MuscleDef("frontalis_R", {17: 0.3, 19: 0.4, 21: 0.3}, {17: 0.3, 19: 0.4, 21: 0.3}, origin_lift=0.7,
              width=1.0, origin_depth=0.06, insertion_depth=0.02, alpha=20),
    # the rest of Viaud & Yahia's list (linear approximations)
    # the orbital part: from the medial palpebral ligament around the eye into the cheek below
    # it; it lifts the cheek toward the eye (cheekSquint)
    MuscleDef("orbicularis_oculi_R", {39: 0.6, 27: 0.4}, {41: 0.3, 36: 0.3, 1: 0.4}, insertion_lift=-0.2,
              width=0.2, origin_depth=0.06, insertion_depth=0.03),
    MuscleDef("nasalis_R", {31: 0.7, 1: 0.3}, {29: 0.7, 39: 0.3}, width=0.08, origin_depth=0.06),
    MuscleDef("levator_labii_superioris_alaeque_nasi_R", {39: 0.6, 28: 0.4}, {31: 0.5, 49: 0.5},
              width=0.07, origin_depth=0.08),
    MuscleDef("levator_labii_superioris_R", {40: 0.6, 41: 0.4}, {49: 0.6, 50: 0.4}, origin_lift=-0.15,
              width=0.1),
    MuscleDef("zygomaticus_minor_R", {0: 0.3, 36: 0.3, 1: 0.4}, {49: 0.7, 48: 0.3}, origin_lift=0.05,
              width=0.08),
    MuscleDef("levator_anguli_oris_R", {31: 0.4, 40: 0.3, 2: 0.3}, {48: 1.0}, origin_lift=-0.05, width=0.08),
    # from the incisive fossa (deep, between the lower lip and the chin) into the chin's skin,
    # which it lifts and pushes the lower lip up (mouthShrugLower)
    MuscleDef("mentalis_R", {57: 0.5, 8: 0.5}, {8: 0.8, 7: 0.2}, insertion_lift=0.05, width=0.1,
              origin_depth=0.12, insertion_depth=0.03),
    MuscleDef("orbicularis_oris_R", {51: 0.5, 57: 0.5}, {48: 1.0}, insertion_out=-0.05, width=0.1,
              origin_depth=0.04),
    MuscleDef("masseter_R", {0: 0.6, 1: 0.4}, {4: 0.7, 5: 0.3}, origin_out=-0.05, width=0.2, origin_depth=0.12,
              insertion_depth=0.1),
    # the rest of what expressions need (the jaw and the lids are drives, rig.drives)
    MuscleDef("frontalis_medial_R", {21: 0.6, 20: 0.4}, {21: 0.6, 20: 0.4}, origin_lift=0.9, width=0.4,
              origin_depth=0.06, insertion_depth=0.02, alpha=20),
    MuscleDef("procerus_R", {27: 1.0}, {21: 0.7, 27: 0.3}, origin_lift=-0.1, insertion_lift=0.1, width=0.1,
              origin_depth=0.06),
    MuscleDef("buccinator_R", {3: 0.6, 4: 0.4}, {48: 1.0}, insertion_out=0.05, width=0.15, origin_depth=0.15,
              insertion_depth=0.06),
    MuscleDef("risorius_R", {2: 0.5, 3: 0.5}, {48: 1.0}, origin_out=-0.1, width=0.1, origin_depth=0.06,
              insertion_depth=0.03),
    MuscleDef("platysma_R", {5: 0.5, 6: 0.5}, {48: 0.6, 59: 0.4}, origin_lift=-0.6, width=0.3, origin_depth=0.05,
              insertion_depth=0.03),
    MuscleDef("temporalis_R", {0: 1.0}, {0: 0.5, 1: 0.5}, origin_lift=0.5, origin_out=0.1, insertion_lift=-0.2,
              width=0.2, origin_depth=0.12, insertion_depth=0.12),
    # orbicularis oris' marginal fibres: from deep behind each lip into its outer skin, they
    # roll the lip inward (mouthRollUpper / mouthRollLower)
    MuscleDef("orbicularis_oris_upper_R", {62: 0.6, 61: 0.4}, {51: 0.5, 50: 0.5}, width=0.15,
              origin_depth=0.15, insertion_depth=0.02),
    MuscleDef("orbicularis_oris_lower_R", {66: 0.6, 67: 0.4}, {57: 0.5, 58: 0.5}, width=0.15,
              origin_depth=0.15, insertion_depth=0.02),
]

# The ICT-FaceKit shape each muscle is calibrated against (tools/calibrate_muscles.py) and
# checked with (bench/simulate.py); nasalis, masseter and temporalis have none (the nostrils;
# they clench and close the jaw)
ICT_SHAPES = {
    "zygomaticus_major_R": "mouthSmile_R", "corrugator_supercilii_R": "browDown_R",
    "depressor_labii_inferioris_R": "mouthLowerDown_R", "depressor_anguli_oris_R": "mouthFrown_R",
    "frontalis_R": "browOuterUp_R", "frontalis_medial_R": "browInnerUp_R", "orbicularis_oculi_R": "cheekSquint_R",
    "levator_labii_superioris_alaeque_nasi_R": "noseSneer_R", "levator_labii_superioris_R": "mouthUpperUp_R",
    "zygomaticus_minor_R": "cheekRaiser_R", "levator_anguli_oris_R": "mouthShrugUpper",
    "mentalis_R": "mouthShrugLower", "orbicularis_oris_R": "mouthPucker",
    "orbicularis_oris_upper_R": "mouthRollUpper", "orbicularis_oris_lower_R": "mouthRollLower",
    "buccinator_R": "mouthDimple_R", "risorius_R": "mouthStretch_R", "platysma_R": "mouthStretch_R",
    "procerus_R": "browDown_R",
}


def coverage_shapes() -> list[str]:
    """ICT-FaceKit's expression shapes that muscles and the jaw make (the coverage figure; what
    calibration's --joint-all fits): all but the gaze (eyeLook*) and the pupils.

    Returns
    -------
    list of str
    """
    return [n for n in shape_names() if not n.startswith(("eyeLook", "Pupil", "identity", "generic"))]


# The placements above are anatomical first guesses; tools/calibrate_muscles.py refines each
# one's offsets, width, depths and reach against its ICT-FaceKit shape on training identities
# (never the held-out ones bench/simulate.py measures) and writes them here:
# (rig/drives.py takes its attachments' numbers from the same file)
_CALIBRATION_FILE = Path(__file__).with_name("calibration.json")
CALIBRATION: dict = json.loads(_CALIBRATION_FILE.read_text()) if _CALIBRATION_FILE.exists() else {}
_RIGHT = [replace(d, **CALIBRATION.get("muscles", {}).get(d.name, {})) for d in _RIGHT]

MUSCLES: dict[str, MuscleDef] = {}
for _d in _RIGHT:
    MUSCLES[_d.name] = _d
    MUSCLES[_d.name[:-2] + "_L"] = _mirror(_d)

KIM_MUSCLES = [n for n in MUSCLES if n.rsplit("_", 1)[0] in
               ("zygomaticus_major", "corrugator_supercilii", "depressor_labii_inferioris", "depressor_anguli_oris")]


# The 28 facial actions (FACS units, Ekman & Friesen), each a group of the library's muscles
# (Viaud & Yahia drive 28 actions with eight groups of forces; "_L"/"_R" both unless named).
FACIAL_ACTIONS = {
    "AU1_inner_brow_raiser": {"frontalis_medial": 1.0},
    "AU2_outer_brow_raiser": {"frontalis": 1.0},
    "AU4_brow_lowerer": {"corrugator_supercilii": 1.0, "procerus": 0.5},
    "AU5_upper_lid_raiser": {"levator_palpebrae": 1.0},
    "AU6_cheek_raiser": {"orbicularis_oculi": 1.0, "zygomaticus_minor": 0.3},
    "AU7_lid_tightener": {"orbicularis_oculi_lower": 1.0, "orbicularis_oculi": 0.3},
    "AU9_nose_wrinkler": {"levator_labii_superioris_alaeque_nasi": 1.0, "nasalis": 0.6, "procerus": 0.5},
    "AU10_upper_lip_raiser": {"levator_labii_superioris": 1.0},
    "AU11_nasolabial_deepener": {"zygomaticus_minor": 1.0},
    "AU12_lip_corner_puller": {"zygomaticus_major": 1.0},
    "AU13_cheek_puffer": {"levator_anguli_oris": 1.0},
    "AU14_dimpler": {"buccinator": 1.0},
    "AU15_lip_corner_depressor": {"depressor_anguli_oris": 1.0},
    "AU16_lower_lip_depressor": {"depressor_labii_inferioris": 1.0},
    "AU17_chin_raiser": {"mentalis": 1.0},
    "AU18_lip_pucker": {"orbicularis_oris": 1.0},
    "AU20_lip_stretcher": {"risorius": 1.0, "platysma": 0.4},
    "AU22_lip_funneler": {"orbicularis_oris": 0.8, "mentalis": 0.2},
    "AU23_lip_tightener": {"orbicularis_oris_upper": 0.6, "orbicularis_oris_lower": 0.6},
    "AU24_lip_pressor": {"orbicularis_oris": 0.7, "mentalis": 0.3},
    "AU25_lips_part": {"depressor_labii_inferioris": 0.5, "digastric": 0.1},
    "AU26_jaw_drop": {"digastric": 0.6, "depressor_labii_inferioris": 0.2},
    "AU27_mouth_stretch": {"digastric": 1.0, "depressor_labii_inferioris": 0.4},
    "AU28_lip_suck": {"orbicularis_oris_upper": 1.0, "orbicularis_oris_lower": 1.0},
    "AU38_nostril_dilator": {"nasalis": -0.8},
    "AU39_nostril_compressor": {"nasalis": 1.0},
    "AU43_eyes_closed": {"orbicularis_oculi_palpebral": 1.0},
    "AU45_blink": {"orbicularis_oculi_palpebral": 1.0},
}


def weights_on(weights: dict, muscle_names) -> np.ndarray:
    """A {muscle: value} map of the library's names (a preset, a facial action) on a rig's muscles:
    a side's muscle ("zygomaticus_major_L") takes its muscle's value ("zygomaticus_major"), else
    its own name's, else 0.  The one place presets and actions reach a rig (anim.Timeline, the
    viewer).

    Parameters
    ----------
    weights : dict
    muscle_names : list of str
        The rig's.

    Returns
    -------
    (len(muscle_names),) float array
    """
    return np.array([float(weights.get(n.rsplit("_", 1)[0], weights.get(n, 0.0))) for n in muscle_names])


def action_activations(action: str, muscle_names) -> np.ndarray:
    """The activations of one facial action for the muscles a rig has.

    Parameters
    ----------
    action : str
        A key of FACIAL_ACTIONS.
    muscle_names : list of str

    Returns
    -------
    (n_muscles,) float array
    """
    if action not in FACIAL_ACTIONS:
        raise MimicaError(f"unknown facial action {action!r}; actions: {', '.join(FACIAL_ACTIONS)}")
    return weights_on(FACIAL_ACTIONS[action], muscle_names)
