"""What the commands on heads (transfer, blendshapes) share: their options on the parser, and the
lines that say what the transfer did to a head (its correspondence, its cuts)."""

from __future__ import annotations

from ..pipeline import TransferOptions
from ._common import MATCH_HELP, _say


def _auto(on: bool) -> str:
    return "auto" if on else "off"


def _head_options(p, what: str) -> None:
    """--show, --match, --cut-mouth and --cut-eyes, the same on transfer and blendshapes."""
    p.add_argument("--show", help=f"PNG: the {what} as the transfer sees it (parts, unmatched skin, the mouth "
                                  "seam, the paired lid rims, the correspondence's confidence)")
    p.add_argument("--match", choices=["nicp", "cylinder"], default=TransferOptions.match, help=MATCH_HELP)
    p.add_argument("--cut-mouth", choices=["auto", "off"], default=_auto(TransferOptions.cut_mouth),
                   help=f"auto: a {what} whose lips are sealed has them cut apart, so the mouth (jawOpen) can "
                        "open (its vertices keep their order; the cut's copies come after them)")
    p.add_argument("--cut-eyes", choices=["auto", "off"], default=_auto(TransferOptions.cut_eyes),
                   help=f"auto: a {what} whose eyes are one surface with the lids has each eye cut loose along "
                        "the lid margin, so the lids close over it (eyeBlink); copies come after the mouth's")


def _correspondence_line(xfer) -> str:
    """'; correspondence (nicp): 99.8% of the target's skin matched, 2.1% with low confidence'."""
    if xfer.relaid:
        return "; the target is the source's own mesh in another vertex layout (found by its uv): solved on its topology"
    cor = xfer.correspondence                  # the skin's, when the heads have parts
    if cor is None:
        return ""
    line = f"; correspondence ({xfer.match}): {100 * cor.matched.mean():.1f}% of the target's skin matched"
    if cor.confidence is not None:
        low = cor.matched & (cor.confidence < cor.LOW)
        line += f", {100 * low.mean():.1f}% with low confidence (< {cor.LOW}; --show draws where)"
    if xfer.paired_eyes:
        line += f"; lid rims paired by arc length: {' and '.join(xfer.paired_eyes)} eye"
    return line


def _say_uncut_mouth(xfer, what, landmarks_flag: str) -> None:
    """One line where sealed lips were left sealed: why, and what to do."""
    if xfer.mouth_uncut is not None:
        _say(f"{what}: the lips are sealed and stay so: {xfer.mouth_uncut.why}; give the head's 68 landmarks "
             f"({landmarks_flag}) so that the mouth's corners and lips are where they are, or say --cut-mouth off "
             "(--show draws where the seam was looked for)")


def _warn_sealed_eyes(xfer, mesh, lm, what, found_flag=None):
    """One line on eyes that are one surface with the lids: cut open, or why not (blinks then
    crease the lids), and on sealed eyes neither cut nor tried (read shut, or --cut-eyes off);
    found_flag: the option that gives landmarks, where they were found on renders (the
    pipeline's result says so)."""
    if xfer.eye_cut is not None:
        ec = xfer.eye_cut
        _say(f"{what}: the {' and '.join(ec.eyes)} eye{'s were' if len(ec.eyes) > 1 else ' was'} one surface with "
             f"the lids: cut loose along the lid margins, {len(ec.copies_of)} vertices added after the others "
             "(--cut-eyes off to keep them whole)")
        if found_flag:
            _say(f"note: {what}: a render barely shows the lids of an eye that is one surface with them, so the "
                 "eyes were cut where the source face's eye, fitted to the surface, puts their margin (on made heads "
                 f"blinks then close 0.82-0.96 of the gap, 0.79-0.89 with the true landmarks): look with --show, "
                 f"and give the head's 68 landmarks ({found_flag}) if the cut is not at the lids' margin")
    if xfer.eyes_uncut:
        whys = "; ".join(dict.fromkeys(xfer.eyes_uncut.values()))
        sides = " and ".join(xfer.eyes_uncut)
        _say(f"note: {what}: the {sides} eye{'s stay' if len(xfer.eyes_uncut) > 1 else ' stays'} one surface with "
             f"the lids ({whys}); blinks crease the lids over {'them' if len(xfer.eyes_uncut) > 1 else 'it'} "
             "instead of closing them")
    if lm is None:
        return
    from ..correspond.mouth import sealed_eyes
    said = set(xfer.eye_cut.eyes if xfer.eye_cut is not None else ()) | set(xfer.eyes_uncut)
    shut = [side for side in sealed_eyes(mesh, lm.positions(mesh)) if side not in said]
    if shut:
        _say(f"note: {what}: the {' and '.join(shut)} eye{'s are' if len(shut) > 1 else ' is'} one closed "
             "surface; lids move over it, they do not open or close")
