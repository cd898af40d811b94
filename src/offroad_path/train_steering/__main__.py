"""`python -m offroad_path.train_steering`."""

from offroad_path.train_steering import main

main()
