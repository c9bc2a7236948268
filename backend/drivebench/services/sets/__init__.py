"""Parameter sets: stored values, compare, upload and download jobs, file formats."""
