"""`python -m offroad_path.predict`."""

from offroad_path.predict import main

main()
