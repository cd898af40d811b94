"""`python -m offroad_path.label`."""

from offroad_path.label import main

main()
