"""Camera motion from stereo video: frame-to-frame stereo visual odometry and its evaluation."""
