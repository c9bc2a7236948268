"""The device profile model, its sections and the catalogue of loaded profiles."""
