"""The oscilloscope: triggered recordings of drive values from several nodes on one time base (issue 31)."""
