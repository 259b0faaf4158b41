"""The exceptions and warnings of sysid."""


class SysidError(Exception):
    """Base class of sysid's errors: what the library refused or could not do."""


class DataError(SysidError, ValueError):
    """Data of the wrong shape or with values the method cannot take."""


class OptionError(SysidError, ValueError):
    """An option out of its range; ``.option`` names the keyword."""

    def __init__(self, message, option=None):
        super().__init__(message)
        self.option = option


class ModelFileError(SysidError, ValueError):
    """A model file that cannot be read: ``.file``, ``.line`` and ``.column`` (1-based)
    say where, as the command line does."""

    def __init__(self, message, file=None, line=None, column=None):
        super().__init__(message)
        self.file = file
        self.line = line
        self.column = column

    def __reduce__(self):
        return (type(self), (str(self), self.file, self.line, self.column))


class UntrustedResultError(SysidError):
    """Raised by ``strict=True`` when a result comes with warnings; ``.result`` holds
    the result and ``.warnings`` the reasons."""

    def __init__(self, message, result=None, warnings=()):
        super().__init__(message)
        self.result = result
        self.warnings = list(warnings)


class SysidWarning(UserWarning):
    """A result that should be read with care (unconverged EM, a filter that lost the
    state, chains that have not mixed, ...)."""
