/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* lftagpublish's MQTT target: one message per frame, in order, to a broker, through
 * libmosquitto. The streaming thread only puts messages in a bounded queue (never
 * blocks); a sender thread of its own hands them to libmosquitto, whose network thread
 * connects, reconnects with exponential back-off and, at QoS 1 and 2, resends what the
 * broker did not acknowledge. While the broker is away the queue fills; once full, new
 * messages are dropped and counted. Built only with libmosquitto (LFTAG_HAVE_MQTT). */
#ifndef __LFTAG_MQTT_SENDER_H__
#define __LFTAG_MQTT_SENDER_H__

#include <gst/gst.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

struct mosquitto;

namespace lftag::gst {

struct MqttSettings {
  std::string host;
  int port = 1883;
  bool tls = false;  // mqtts:// or a CA file
  std::string topic, client_id, username, password, ca_file, cert_file, key_file;
  int qos = 1;
  std::size_t queue_size = 1000;
};

/* "host", "host:port", "[v6]:port", "mqtt://host[:port]" or "mqtts://host[:port]" (TLS,
 * port 8883 by default) into `out`. False, with `why` set, for anything else. */
bool parse_broker(const std::string& address, MqttSettings& out, std::string& why);

class MqttSender {
 public:
  /* Warnings, infos and errors go to `element`'s bus. */
  explicit MqttSender(GstElement* element) : element_(element) {}
  ~MqttSender() { stop(); }
  MqttSender(const MqttSender&) = delete;
  MqttSender& operator=(const MqttSender&) = delete;

  /* Sets up the client and starts connecting (in the background: a broker not there yet
   * is waited for). False, with `why` saying what to fix, for a configuration that cannot
   * work (a TLS file that does not load, a topic with wildcards...). */
  bool start(const MqttSettings& settings, std::string& why);
  /* Queues one message; never blocks. False when the queue is full and it was dropped. */
  bool push(std::string payload);
  /* Waits up to `timeout` for every queued message to be handed over and, at QoS 1 and
   * 2, acknowledged. The number still not delivered. */
  std::size_t flush(std::chrono::milliseconds timeout);
  /* Disconnects and ends the threads; what is still queued is lost (flush() first). */
  void stop();

  std::uint64_t dropped() const;
  std::uint64_t sent() const;

 private:
  bool connect_first();
  void send_loop();
  void on_connect(int rc);
  void on_disconnect(int rc);
  void on_publish();

  GstElement* element_;
  MqttSettings settings_;
  struct mosquitto* mosq_ = nullptr;
  std::thread sender_;

  mutable std::mutex lock_;
  std::condition_variable changed_;
  std::deque<std::string> queue_;
  std::size_t in_flight_ = 0; /* handed to libmosquitto, not yet acknowledged */
  bool connected_ = false, ever_connected_ = false, stopping_ = false, overflowing_ = false;
  bool warned_unreachable_ = false;
  std::uint64_t dropped_ = 0, sent_ = 0;
};

}  // namespace lftag::gst

#endif /* __LFTAG_MQTT_SENDER_H__ */
