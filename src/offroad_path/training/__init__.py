"""Training: the Lightning task, pretrained initialisation, and the run shared by `pretrain` and `train`."""
