"""Running the trained models over patches and cities."""
