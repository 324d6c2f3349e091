"""The one error type a user can cause (DESIGN.md, Conventions)."""


class MimicaError(Exception):
    """A problem with the user's input: the message names the input and what to do.

    The command line prints it on one line and exits non-zero, without a traceback.
    """


class NeedsLandmarks(MimicaError):
    """A MimicaError for a mesh whose landmarks were neither given nor found: `which` says which
    of a job's meshes ("source", "target", "head"), so that a front end can name its own way of
    giving them."""

    def __init__(self, message: str, which: str = "head"):
        super().__init__(message)
        self.which = which
