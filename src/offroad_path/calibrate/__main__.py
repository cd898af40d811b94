"""`python -m offroad_path.calibrate`."""

from offroad_path.calibrate import main

main()
