/* The stop-and-wait bound of a link: one process writes a packet (132 or 1029 bytes) and waits for
 * a 1-byte reply, another reads the whole packet and replies, ROUNDS times. Prints payload bytes/s
 * (PAYLOAD per round): the fastest any XModem pair can go over this link, because an XModem pair
 * does at least this much per block. Plain blocking read()/write() in two processes, so that the
 * measuring program's own cost per round is as small as it can be (a Python loop was slower than
 * cnc_dnc itself on 132-byte packets, so it was no bound).
 *
 * usage: stop_and_wait DEV_A DEV_B ROUNDS [PACKET_BYTES] [PAYLOAD_BYTES]
 */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

static int open_raw(const char* path)
{
  int fd = open(path, O_RDWR | O_NOCTTY);
  struct termios tio;
  if (fd < 0 || tcgetattr(fd, &tio) != 0)
  {
    perror(path);
    exit(1);
  }
  cfmakeraw(&tio);
  tcsetattr(fd, TCSANOW, &tio);
  return fd;
}

static void read_exactly(int fd, unsigned char* buffer, size_t size)
{
  for (size_t done = 0; done < size;)
  {
    ssize_t n = read(fd, buffer + done, size - done);
    if (n <= 0)
    {
      perror("read");
      exit(1);
    }
    done += (size_t)n;
  }
}

int main(int argc, char** argv)
{
  if (argc < 4)
  {
    fprintf(stderr, "usage: %s DEV_A DEV_B ROUNDS [PACKET_BYTES] [PAYLOAD_BYTES]\n", argv[0]);
    return 2;
  }
  const long rounds = atol(argv[3]);
  const size_t packet = argc > 4 ? (size_t)atol(argv[4]) : 132;
  const size_t payload = argc > 5 ? (size_t)atol(argv[5]) : 128;
  static unsigned char block[4096];
  unsigned char reply = 0x06;
  if (packet > sizeof(block))
    return 2;
  const int a = open_raw(argv[1]);
  const int b = open_raw(argv[2]);
  const pid_t echo = fork();
  if (echo == 0)
  {
    for (long i = 0; i < rounds; ++i)
    {
      read_exactly(b, block, packet);
      if (write(b, &reply, 1) != 1)
        _exit(1);
    }
    _exit(0);
  }
  struct timespec start, end;
  clock_gettime(CLOCK_MONOTONIC, &start);
  for (long i = 0; i < rounds; ++i)
  {
    if (write(a, block, packet) != (ssize_t)packet)
    {
      perror("write");
      return 1;
    }
    read_exactly(a, &reply, 1);
  }
  clock_gettime(CLOCK_MONOTONIC, &end);
  waitpid(echo, NULL, 0);
  const double seconds = (double)(end.tv_sec - start.tv_sec) + (double)(end.tv_nsec - start.tv_nsec) / 1e9;
  printf("%.0f\n", (double)rounds * (double)payload / seconds);
  return 0;
}
