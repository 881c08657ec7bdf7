"""Errors the engine raises for problems a user can fix."""


class AasdfError(RuntimeError):
    """A request the engine refuses: bad input, or a resolution too fine for the machine's memory."""
