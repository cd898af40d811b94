"""`python -m offroad_path.export`."""

from offroad_path.export import main

main()
