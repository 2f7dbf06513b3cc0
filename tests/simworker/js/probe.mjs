// Drive one simulated endpoint with the npm roslib client; print what it saw as JSON.
// Usage: node probe.mjs <ws url> <cmd topic> <odom topic> <speed>
import { Ros, Topic, Param } from "roslib";

const [url, cmdTopic, odomTopic, speed] = process.argv.slice(2);
const ros = new Ros({ url });
const call = (fn, ...args) => new Promise((resolve, reject) => fn.call(ros, ...args, resolve, reject));
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

ros.on("error", (e) => { console.error(String(e)); process.exit(2); });
ros.on("connection", async () => {
  const out = {};
  out.topics = await call(ros.getTopics);
  out.nodes = await call(ros.getNodes);
  out.services = await call(ros.getServices);
  out.description = await new Promise((res, rej) =>
    new Param({ ros, name: "/robot_description" }).get(res, rej));
  const odom = [];
  const listener = new Topic({ ros, name: odomTopic, messageType: "nav_msgs/Odometry" });
  listener.subscribe((m) => odom.push(m.twist.twist.linear.x));
  const cmd = new Topic({ ros, name: cmdTopic, messageType: "geometry_msgs/Twist" });
  for (let i = 0; i < 12; i++) {
    cmd.publish({ linear: { x: Number(speed), y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } });
    await sleep(100);
  }
  listener.unsubscribe();
  out.speeds = odom;
  console.log(JSON.stringify(out));
  ros.close();
  process.exit(0);
});
