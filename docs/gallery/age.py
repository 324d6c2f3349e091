"""Wrinkles that follow age and expression

Viaud and Yahia's wrinkles on ICT-FaceKit's neutral face: the reference wrinkle mask carried
onto it, the bulges' depth set by age (columns) and by how far the skin is compressed (the
second row smiles, driven by the muscle rig).  One call of the pipeline, as `mimica age` draws it.
"""
import sys

from mimica.data import ICT_HEAD_VERTICES, ICTModel
from mimica.pipeline import AgeOptions, age_sheet

face = ICTModel(ICT_HEAD_VERTICES).mesh                       # the head without its eyes and mouth
age_sheet(face, sys.argv[1], options=AgeOptions(ages=(30.0, 55.0, 80.0), size=300))
