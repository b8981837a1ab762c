"""Pictures for people: imagery with ground truth (and later predictions) drawn over it."""
