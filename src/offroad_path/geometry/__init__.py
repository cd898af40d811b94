"""Geometry every stage shares: stereo disparity and depth (`stereo`), and the driven path's
distance and mirroring (`path`)."""
