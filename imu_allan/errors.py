"""The one exception type for bad input: its message is the one line a user sees."""


class InputError(ValueError):
    """Bad input (file, argument or data), reported as ``'<where>: <problem>'``."""

    def __init__(self, where, problem):
        """Store where (a file or argument name) and what is wrong."""
        super().__init__(f'{where}: {problem}')
        self.where = str(where)
        self.problem = problem
