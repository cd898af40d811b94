"""`python -m offroad_path.split`."""

from offroad_path.split import main

main()
