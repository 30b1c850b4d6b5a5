"""Biber & Duckett 2009, "Experimental analysis of sample-based maps for long-term SLAM", §5."""
