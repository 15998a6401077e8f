//! A minimal viewer speaking Foxglove's WebSocket protocol (`foxglove.sdk.v1`: JSON `serverInfo`
//! and `advertise`, JSON `subscribe`, binary `messageData` = opcode 0x01, subscription id u32 LE,
//! log time u64 LE, payload), written from the protocol description rather than with the server's
//! code, for the tests of the live view. A viewer that connects and then never reads (with a tiny
//! receive buffer) stands for an unresponsive Foxglove.

use std::collections::BTreeMap;
use std::io::ErrorKind;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

/// An advertised channel.
#[derive(Clone, Debug)]
pub struct Advertised {
    pub id: u64,
    pub topic: String,
    pub encoding: String,
    pub schema_name: String,
}

/// One received message.
#[derive(Clone, Debug)]
pub struct Received {
    pub topic: String,
    pub schema_name: String,
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// A connected viewer.
pub struct Viewer {
    ws: WebSocket<TcpStream>,
    /// Channels advertised so far, by id.
    pub channels: BTreeMap<u64, Advertised>,
    subscriptions: BTreeMap<u32, u64>,
    next_subscription: u32,
}

type R<T> = Result<T, String>;

impl Viewer {
    /// Connects to `url` (`ws://host:port`) offering subprotocol `foxglove.sdk.v1`;
    /// `recv_buffer` shrinks the socket's receive buffer (bytes) before connecting.
    pub fn connect(url: &str, recv_buffer: Option<usize>) -> R<Self> {
        let hostport = url.strip_prefix("ws://").ok_or_else(|| format!("{url}: not ws://"))?;
        let addr = hostport
            .to_socket_addrs()
            .map_err(|e| format!("{url}: {e}"))?
            .next()
            .ok_or_else(|| format!("{url}: no address"))?;
        let socket = socket2::Socket::new(socket2::Domain::for_address(addr), socket2::Type::STREAM, None)
            .map_err(|e| e.to_string())?;
        if let Some(b) = recv_buffer {
            socket.set_recv_buffer_size(b).map_err(|e| e.to_string())?;
        }
        socket.connect_timeout(&addr.into(), Duration::from_secs(10)).map_err(|e| format!("{url}: {e}"))?;
        let stream: TcpStream = socket.into();
        let mut req = url.into_client_request().map_err(|e| e.to_string())?;
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            "foxglove.sdk.v1".parse().map_err(|e: tungstenite::http::header::InvalidHeaderValue| e.to_string())?,
        );
        let (ws, resp) = tungstenite::client(req, stream).map_err(|e| format!("{url}: handshake: {e}"))?;
        let proto = resp.headers().get("sec-websocket-protocol").and_then(|v| v.to_str().ok()).unwrap_or("");
        if proto != "foxglove.sdk.v1" {
            return Err(format!("server chose subprotocol `{proto}`"));
        }
        Ok(Self { ws, channels: BTreeMap::new(), subscriptions: BTreeMap::new(), next_subscription: 1 })
    }

    /// Reads one frame (None on timeout). Text frames update the channel list; binary
    /// `messageData` frames come back decoded.
    pub fn read(&mut self, timeout: Duration) -> R<Option<Received>> {
        self.ws.get_mut().set_read_timeout(Some(timeout.max(Duration::from_millis(1)))).map_err(|e| e.to_string())?;
        let msg = match self.ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e)) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Ok(None)
            }
            Err(e) => return Err(format!("read: {e}")),
        };
        match msg {
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(t.as_str()).map_err(|e| format!("{e}: {t}"))?;
                match v.get("op").and_then(|o| o.as_str()) {
                    Some("advertise") => {
                        for c in v.get("channels").and_then(|c| c.as_array()).into_iter().flatten() {
                            let s = |k: &str| c.get(k).and_then(|x| x.as_str()).unwrap_or("").to_string();
                            let id = c.get("id").and_then(|x| x.as_u64()).ok_or("advertise without id")?;
                            self.channels.insert(
                                id,
                                Advertised {
                                    id,
                                    topic: s("topic"),
                                    encoding: s("encoding"),
                                    schema_name: s("schemaName"),
                                },
                            );
                        }
                    }
                    Some("unadvertise") => {
                        for id in v.get("channelIds").and_then(|c| c.as_array()).into_iter().flatten() {
                            if let Some(id) = id.as_u64() {
                                self.channels.remove(&id);
                            }
                        }
                    }
                    _ => {}
                }
                Ok(None)
            }
            Message::Binary(b) => {
                if b.len() < 13 || b[0] != 0x01 {
                    return Ok(None);
                }
                let sub = u32::from_le_bytes([b[1], b[2], b[3], b[4]]);
                let mut t = [0u8; 8];
                t.copy_from_slice(&b[5..13]);
                let ch =
                    self.subscriptions.get(&sub).ok_or_else(|| format!("message for unknown subscription {sub}"))?;
                let a = self.channels.get(ch).ok_or_else(|| format!("message on unknown channel {ch}"))?;
                Ok(Some(Received {
                    topic: a.topic.clone(),
                    schema_name: a.schema_name.clone(),
                    log_time: u64::from_le_bytes(t),
                    data: b[13..].to_vec(),
                }))
            }
            _ => Ok(None),
        }
    }

    /// Waits (up to `timeout`) until at least `n` channels are advertised, then subscribes to
    /// every advertised channel not yet subscribed.
    pub fn subscribe_all(&mut self, n: usize, timeout: Duration) -> R<Vec<Advertised>> {
        let t0 = Instant::now();
        while self.channels.len() < n {
            if t0.elapsed() > timeout {
                return Err(format!("only {} of {n} channels advertised", self.channels.len()));
            }
            self.read(Duration::from_millis(100))?;
        }
        let mut subs = Vec::new();
        let subscribed: Vec<u64> = self.subscriptions.values().copied().collect();
        for c in self.channels.values().filter(|c| !subscribed.contains(&c.id)) {
            subs.push(serde_json::json!({ "id": self.next_subscription, "channelId": c.id }));
            self.subscriptions.insert(self.next_subscription, c.id);
            self.next_subscription += 1;
        }
        let msg = serde_json::json!({ "op": "subscribe", "subscriptions": subs }).to_string();
        self.ws.send(Message::text(msg)).map_err(|e| format!("subscribe: {e}"))?;
        Ok(self.channels.values().cloned().collect())
    }

    /// Closes the connection.
    pub fn close(mut self) {
        let _ = self.ws.close(None);
        let _ = self.ws.flush();
    }
}
