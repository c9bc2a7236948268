"""Line addressing with LSS (CiA 305): the steps on a session's bus, their safety rule and their audit rows."""
