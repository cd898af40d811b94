"""`python -m offroad_path.train`."""

from offroad_path.train import main

main()
