"""Errors raised by the Robot Hardware Abstraction Layer.

Every error RHAL raises on purpose is a :class:`RhalError`, so a caller can catch them all::

    Exception
     +-- RhalError
          +-- UnknownDriverError      no driver for this URL scheme
          +-- DriverUnavailableError  the driver needs a library that is not installed
          +-- NotSupportedError       this robot lacks the capability or sensor asked for
          +-- RobotConnectionError    the robot cannot be opened, is not open, or its link dropped

Bad arguments (a speed that is not a number, an unknown option) raise the built-in
``ValueError`` / ``TypeError``, as any Python API does.
"""


class RhalError(Exception):
    """Base class of every RHAL error."""


class UnknownDriverError(RhalError):
    """The robot URL names a scheme no driver is registered for."""


class DriverUnavailableError(RhalError):
    """The driver exists but an optional library it needs is missing."""


class NotSupportedError(RhalError):
    """The robot has no such capability or sensor."""


class RobotConnectionError(RhalError):
    """The robot cannot be reached: opening failed, it is closed, or the link was lost."""
