"""`python -m offroad_path.drive`."""

from offroad_path.drive import main

main()
