# Sourced by the project's scripts. ROS 1 on Debian runs on the system Python (/usr/bin/python3,
# which has rospkg and catkin_pkg); a python3 earlier on PATH (a virtualenv, pyenv) would break
# roslaunch, rostest and the message generators, so the system directories go first.
export PATH="/usr/bin:/bin:$PATH"
# ccache: paths below the checkout are hashed relative to it, so every clone and build directory
# shares one cache.
export CCACHE_BASEDIR="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export CCACHE_NOHASHDIR=1
