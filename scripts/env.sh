# Sourced by the project's scripts. ROS 1 on Debian runs on the system Python (/usr/bin/python3,
# which has rospkg and catkin_pkg); a python3 earlier on PATH (a virtualenv, pyenv) would break
# roslaunch, rostest and the message generators, so the system directories go first.
export PATH="/usr/bin:/bin:$PATH"
export CCACHE_NOHASHDIR=1
