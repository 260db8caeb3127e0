//! RGB-D datasets: TUM, Replica, and the embedded synthetic room.
