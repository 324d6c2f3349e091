"""The one error type a user can cause (DESIGN.md, Conventions)."""


class MimicaError(Exception):
    """A problem with the user's input: the message names the input and what to do.

    The command line prints it on one line and exits non-zero, without a traceback.
    """
