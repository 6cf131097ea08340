"""The HTML report of a diagnosis."""
