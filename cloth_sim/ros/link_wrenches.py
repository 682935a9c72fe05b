"""``~/robots/<robot>/<link>/wrench``: what the cloth exerts on each link of each robot in the
scene, every tick (``geometry_msgs/WrenchStamped``, world frame, torque about the link's origin):
what a finger feels when it holds the cloth by friction
(:meth:`cloth_sim.simulator.Simulator.link_wrench`). The topics follow the robots: a robot that
comes (a scene's, a description's, a spawned one) gets its links' topics, one that goes takes
them along."""

from __future__ import annotations

from geometry_msgs.msg import WrenchStamped

from . import interface, messages


class LinkWrenches:
    def __init__(self, node, session):
        self.node, self.session = node, session
        self.pubs: dict[tuple[str, str], object] = {}

    def _sync(self) -> None:
        robots = self.session.sim.robots
        wanted = {(r, link) for r, robot in robots.items() for link in robot.link_names}
        for key in set(self.pubs) - wanted:
            self.node.destroy_publisher(self.pubs.pop(key))
        for r, link in sorted(wanted - set(self.pubs)):
            self.pubs[(r, link)] = interface.publisher(
                self.node, "link_wrench", WrenchStamped, name=f"{r}/{link}"
            )

    def publish(self, frame: str, stamp) -> None:
        self._sync()
        sim = self.session.sim
        for (r, link), pub in self.pubs.items():
            force, torque = sim.link_wrench(r, link)
            pub.publish(messages.wrench(force, torque, frame, stamp))
