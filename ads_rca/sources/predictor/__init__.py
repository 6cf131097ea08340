"""A predictor's tracks scored against the realised future, where the verdict rules cannot
judge prediction."""
