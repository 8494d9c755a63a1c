"""Errors a user can cause and fix, as opposed to bugs.

The CLI prints a :class:`UserError` as one line and exits with status 2, with no traceback.
"""


class UserError(ValueError):
    """Bad input from a user: a malformed scenario, an unknown name, a NaN in an action.

    The message says what and where (file, field, value) in one line.
    """
