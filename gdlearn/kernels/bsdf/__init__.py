"""The BSDFs of the Mitsuba 3 subset, one plugin per file, behind ``dispatch``."""
