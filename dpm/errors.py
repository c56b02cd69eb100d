"""The one exception type for bad user input; the command-line tools print it and exit 2."""


class InputError(Exception):
    """A file, scene or option that dpm cannot use; the message names the file and the problem."""
