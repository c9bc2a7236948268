"""Device description files: CiA 306 EDS/DCF and CiA 311 XDD/XDC import and export, and their text."""
