"""The one error type a user can cause (DESIGN.md, Conventions)."""


class MimicaError(Exception):
    """A problem with the user's input: the message names the input and what to do.

    The command line prints it on one line and exits non-zero, without a traceback.

    Parameters
    ----------
    message : str
        One line: the input (a file, an option, a value) and what to do about it.
    """


class NeedsLandmarks(MimicaError):
    """A MimicaError for a mesh whose landmarks were neither given nor found.

    Parameters
    ----------
    message : str
        The library's line (naming the mesh, not a front end's option).
    which : str
        Which of a job's meshes: "source", "target" or "head", so that a front end can name its
        own way of giving them.
    """

    def __init__(self, message: str, which: str = "head"):
        super().__init__(message)
        self.which = which
