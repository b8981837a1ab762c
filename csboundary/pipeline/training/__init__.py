"""Workflows that change the weights for a user's city: fine-tuning on labelled areas (and its
cross-validation), self-training on unlabelled imagery (``adapt``), fitting the edge confidence."""
