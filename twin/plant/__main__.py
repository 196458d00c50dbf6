"""``python -m twin.plant MACHINE -o FILE.xml [--scene]``: export a machine's MJCF for
MuJoCo's viewer (`twin.plant.model.main`)."""

from twin.plant.model import main

main()
