import sys

from motiongan_jax.demo.server import main

sys.exit(main())
