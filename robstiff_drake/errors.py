"""The one error type that the command line turns into a one-line message
and exit status 2 (bad input: a file, a value, a key)."""


class InputError(Exception):
    """Bad input from the user. The message says what is wrong and where."""


class SingularPoseError(ValueError):
    """A stiffness-form quantity was asked for where J is not invertible.

    Attributes:
        joints: 1-based joint numbers that take part in the lost direction.
    """

    def __init__(self, message, joints):
        super().__init__(message)
        self.joints = tuple(joints)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every cleanup runs (a
    temporary file or folder removed, a worker pool stopped); a long-running
    command (compensate) ends its run on it as on Ctrl-C."""
