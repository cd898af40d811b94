"""`python -m offroad_path.pretrain`."""

from offroad_path.pretrain import main

main()
