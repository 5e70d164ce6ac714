"""Named checks of a recording and its measurement table (pure functions)."""
