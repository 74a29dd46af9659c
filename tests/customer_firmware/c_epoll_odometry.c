/* A differential-drive odometry firmware written as a customer would write it, knowing nothing
 * of wheelhil: plain SocketCAN, a timerfd + epoll main loop on CLOCK_MONOTONIC, a reader thread
 * blocked in read() that shares the latest encoder counts under a mutex. It is the CANopen
 * master of two CiA 406 encoders: it waits for their boot-up, makes each one's TPDO1
 * synchronous by SDO (0x1800:02 = 1), starts them (NMT), produces SYNC every period and publishes its pose in its own
 * frames:
 *   0x3A0 (8 bytes): x, y   int32 little endian, 0.1 mm
 *   0x3A1 (8 bytes): theta  int32 little endian, microradians; cycle uint32
 * Usage: c_epoll_odometry --can IFACE [--left ID] [--right ID] [--cpr N] [--radius M]
 *                         [--track M] [--period-ms N] [--spin-after-s S] [--exit-after-s S]
 *                         [--fork] [--raw-sleep-after-s S] [--superloop 1]
 *                         [--abort-after-bind 1] [--reexec-without LIB] [--self-pipe 1]
 * --fork: the work is done by a forked child; the parent only waits for it (a supervisor).
 * --superloop: the main loop never blocks: it polls its epoll set with a zero timeout, as a
 * bare-metal super loop ported to Linux does.
 * --spin-after-s: after S seconds, busy-wait on epoll with a zero timeout forever; --exit-after-s:
 * after S seconds, exit with status 3; --raw-sleep-after-s: after S seconds, sleep 1 ms of the
 * host's clock each cycle through a raw system call, as a Go runtime makes it (tests of what the
 * emulator reports for such firmware); --abort-after-bind: abort() as soon as the bus is open;
 * --reexec-without LIB: first exec itself again with every LD_PRELOAD entry naming LIB dropped,
 * as a launcher that cleans its environment does; --self-pipe: the read end of a pipe (written
 * by its SIGTERM handler) is in the epoll set too, the classic way to wake a loop on a signal. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <math.h>
#include <net/if.h>
#include <pthread.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/timerfd.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

struct node {
  int id;
  int booted;
  int sdo_answered;
  uint32_t position;
  int have_position;
};

static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static struct node g_nodes[2];
static volatile sig_atomic_t g_stop = 0;
static int g_can = -1;
static int g_wake_pipe[2] = {-1, -1};

static void on_signal(int sig) {
  (void)sig;
  g_stop = 1;
  if (g_wake_pipe[1] >= 0) {
    const char c = 1;
    (void)!write(g_wake_pipe[1], &c, 1);
  }
}

static int send_frame(uint32_t id, const uint8_t* data, uint8_t len) {
  struct can_frame f;
  memset(&f, 0, sizeof(f));
  f.can_id = id;
  f.can_dlc = len;
  if (len > 0) memcpy(f.data, data, len);
  return write(g_can, &f, sizeof(f)) == (ssize_t)sizeof(f) ? 0 : -1;
}

static void* reader(void* arg) {
  (void)arg;
  struct can_frame f;
  while (!g_stop) {
    const ssize_t n = read(g_can, &f, sizeof(f));
    if (n < 0) {
      if (errno == EINTR) continue;
      break;
    }
    if (n != (ssize_t)sizeof(f)) continue;
    pthread_mutex_lock(&g_lock);
    for (int i = 0; i < 2; ++i) {
      struct node* nd = &g_nodes[i];
      if (f.can_id == 0x700u + (uint32_t)nd->id && f.can_dlc == 1 && f.data[0] == 0) {
        nd->booted = 1;
      } else if (f.can_id == 0x580u + (uint32_t)nd->id && f.can_dlc == 8 && f.data[0] == 0x60 &&
                 f.data[1] == 0x00 && f.data[2] == 0x18 && f.data[3] == 0x02) {
        nd->sdo_answered = 1;
      } else if (f.can_id == 0x180u + (uint32_t)nd->id && f.can_dlc >= 4) {
        nd->position = (uint32_t)f.data[0] | (uint32_t)f.data[1] << 8 | (uint32_t)f.data[2] << 16 |
                       (uint32_t)f.data[3] << 24;
        nd->have_position = 1;
      }
    }
    pthread_mutex_unlock(&g_lock);
  }
  return NULL;
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void put_i32(uint8_t* p, int32_t v) {
  const uint32_t u = (uint32_t)v;
  p[0] = (uint8_t)u;
  p[1] = (uint8_t)(u >> 8);
  p[2] = (uint8_t)(u >> 16);
  p[3] = (uint8_t)(u >> 24);
}

/* nanosleep without any libc symbol: a `syscall` instruction of the program's own. */
static long raw_nanosleep(const struct timespec* ts) {
#if defined(__x86_64__)
  long ret;
  __asm__ volatile("syscall"
                   : "=a"(ret)
                   : "a"((long)SYS_nanosleep), "D"(ts), "S"((const struct timespec*)NULL)
                   : "rcx", "r11", "memory");
  return ret;
#else
  return syscall(SYS_nanosleep, ts, NULL);
#endif
}

int main(int argc, char** argv) {
  const char* iface = NULL;
  int cpr = 2000;
  double radius = 0.075, track = 0.32, spin_after_s = -1, exit_after_s = -1;
  double raw_sleep_after_s = -1;
  int fork_child = 0;
  int superloop = 0;
  int self_pipe = 0;
  int abort_after_bind = 0;
  const char* reexec_without = NULL;
  int period_ms = 10;
  g_nodes[0].id = 1;
  g_nodes[1].id = 2;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (strcmp(argv[i], "--can") == 0) iface = argv[i + 1];
    else if (strcmp(argv[i], "--left") == 0) g_nodes[0].id = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--right") == 0) g_nodes[1].id = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--cpr") == 0) cpr = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--radius") == 0) radius = atof(argv[i + 1]);
    else if (strcmp(argv[i], "--track") == 0) track = atof(argv[i + 1]);
    else if (strcmp(argv[i], "--period-ms") == 0) period_ms = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--spin-after-s") == 0) spin_after_s = atof(argv[i + 1]);
    else if (strcmp(argv[i], "--exit-after-s") == 0) exit_after_s = atof(argv[i + 1]);
    else if (strcmp(argv[i], "--fork") == 0) fork_child = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--superloop") == 0) superloop = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--raw-sleep-after-s") == 0) raw_sleep_after_s = atof(argv[i + 1]);
    else if (strcmp(argv[i], "--abort-after-bind") == 0) abort_after_bind = atoi(argv[i + 1]);
    else if (strcmp(argv[i], "--reexec-without") == 0) reexec_without = argv[i + 1];
    else if (strcmp(argv[i], "--self-pipe") == 0) self_pipe = atoi(argv[i + 1]);
  }
  if (reexec_without != NULL) {
    /* LD_PRELOAD without the entries naming the library; the same arguments but this pair. */
    const char* old = getenv("LD_PRELOAD");
    char kept[4096] = "";
    char* list = strdup(old != NULL ? old : "");
    for (char* save = NULL, *e = strtok_r(list, ": ", &save); e != NULL; e = strtok_r(NULL, ": ", &save)) {
      if (strstr(e, reexec_without) != NULL || strlen(kept) + strlen(e) + 2 > sizeof(kept)) continue;
      if (kept[0] != '\0') strcat(kept, ":");
      strcat(kept, e);
    }
    free(list);
    setenv("LD_PRELOAD", kept, 1);
    char** args = calloc((size_t)argc + 1, sizeof(char*));
    int n = 0;
    for (int i = 0; i < argc; ++i) {
      if (strcmp(argv[i], "--reexec-without") == 0) {
        ++i;
        continue;
      }
      args[n++] = argv[i];
    }
    execv("/proc/self/exe", args);
    perror("c_epoll_odometry: exec");
    return 1;
  }
  if (iface == NULL) {
    fprintf(stderr, "usage: %s --can IFACE ...\n", argv[0]);
    return 2;
  }
  if (fork_child) {
    const pid_t child = fork();
    if (child < 0) {
      perror("c_epoll_odometry: fork");
      return 1;
    }
    if (child > 0) {
      int status = 0;
      while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
      }
      return WIFEXITED(status) ? WEXITSTATUS(status) : 1;
    }
  }
  struct sigaction sa;
  memset(&sa, 0, sizeof(sa));
  sa.sa_handler = on_signal;
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGINT, &sa, NULL);

  g_can = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  struct ifreq ifr;
  memset(&ifr, 0, sizeof(ifr));
  strncpy(ifr.ifr_name, iface, IFNAMSIZ - 1);
  if (g_can < 0 || ioctl(g_can, SIOCGIFINDEX, &ifr) < 0) {
    perror("c_epoll_odometry: socket/SIOCGIFINDEX");
    return 1;
  }
  struct sockaddr_can addr;
  memset(&addr, 0, sizeof(addr));
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (bind(g_can, (struct sockaddr*)&addr, sizeof(addr)) < 0) {
    perror("c_epoll_odometry: bind");
    return 1;
  }
  if (abort_after_bind) abort();
  pthread_t rx;
  pthread_create(&rx, NULL, reader, NULL);

  const int tfd = timerfd_create(CLOCK_MONOTONIC, TFD_CLOEXEC);
  struct itimerspec its;
  memset(&its, 0, sizeof(its));
  its.it_value.tv_nsec = (long)period_ms * 1000000L;
  its.it_interval.tv_nsec = (long)period_ms * 1000000L;
  timerfd_settime(tfd, 0, &its, NULL);
  const int ep = epoll_create1(EPOLL_CLOEXEC);
  struct epoll_event ev;
  memset(&ev, 0, sizeof(ev));
  ev.events = EPOLLIN;
  ev.data.fd = tfd;
  epoll_ctl(ep, EPOLL_CTL_ADD, tfd, &ev);
  if (self_pipe && pipe2(g_wake_pipe, O_CLOEXEC | O_NONBLOCK) == 0) {
    ev.data.fd = g_wake_pipe[0];
    epoll_ctl(ep, EPOLL_CTL_ADD, g_wake_pipe[0], &ev);
  }

  enum { kWaitBoot, kWaitSdo, kRun } state = kWaitBoot;
  const double t0 = now_s();
  double boot_wait_until = t0 + 1.0;
  double x = 0, y = 0, theta = 0;
  uint32_t last[2] = {0, 0};
  int have_last = 0;
  uint32_t cycle = 0;
  while (!g_stop) {
    if (spin_after_s >= 0 && now_s() - t0 > spin_after_s) {
      struct epoll_event out;
      for (;;) epoll_wait(ep, &out, 1, 0);  // a firmware bug: it never blocks again
    }
    if (exit_after_s >= 0 && now_s() - t0 > exit_after_s) exit(3);
    if (raw_sleep_after_s >= 0 && now_s() - t0 > raw_sleep_after_s) {
      const struct timespec ms = {0, 1000000};
      raw_nanosleep(&ms);
    }
    struct epoll_event out;
    const int n = epoll_wait(ep, &out, 1, superloop ? 0 : -1);
    if (n == 0) continue;  /* the super loop: nothing ready yet */
    if (n < 0) {
      if (errno == EINTR) continue;
      perror("c_epoll_odometry: epoll_wait");
      return 1;
    }
    if (g_wake_pipe[0] >= 0 && out.data.fd == g_wake_pipe[0]) continue;  /* a signal: g_stop */
    uint64_t expirations = 0;
    if (read(tfd, &expirations, sizeof(expirations)) != (ssize_t)sizeof(expirations)) continue;

    pthread_mutex_lock(&g_lock);
    const int booted = g_nodes[0].booted && g_nodes[1].booted;
    const int answered = g_nodes[0].sdo_answered && g_nodes[1].sdo_answered;
    const int have = g_nodes[0].have_position && g_nodes[1].have_position;
    const uint32_t pos[2] = {g_nodes[0].position, g_nodes[1].position};
    pthread_mutex_unlock(&g_lock);

    if (state == kWaitBoot && (booted || now_s() > boot_wait_until)) {
      for (int i = 0; i < 2; ++i) {
        const uint8_t download[8] = {0x2F, 0x00, 0x18, 0x02, 1, 0, 0, 0};  // 0x1800:02 = 1
        send_frame(0x600u + (uint32_t)g_nodes[i].id, download, 8);
      }
      state = kWaitSdo;
      continue;
    }
    if (state == kWaitSdo && answered) {
      const uint8_t start[2] = {0x01, 0x00};  // NMT start, all nodes
      send_frame(0x000, start, 2);
      state = kRun;
      continue;
    }
    if (state != kRun) continue;
    send_frame(0x080, NULL, 0);  // SYNC
    if (have) {
      if (have_last) {
        const double k = 2.0 * M_PI * radius / cpr;
        const double dl = (double)(int32_t)(pos[0] - last[0]) * k;
        const double dr = (double)(int32_t)(pos[1] - last[1]) * k;
        const double ds = 0.5 * (dl + dr), dth = (dr - dl) / track;
        x += ds * cos(theta + 0.5 * dth);
        y += ds * sin(theta + 0.5 * dth);
        theta += dth;
      }
      last[0] = pos[0];
      last[1] = pos[1];
      have_last = 1;
    }
    uint8_t d[8];
    put_i32(d, (int32_t)lround(x * 1e4));
    put_i32(d + 4, (int32_t)lround(y * 1e4));
    send_frame(0x3A0, d, 8);
    put_i32(d, (int32_t)lround(theta * 1e6));
    put_i32(d + 4, (int32_t)cycle++);
    send_frame(0x3A1, d, 8);
  }
  return 0;
}
